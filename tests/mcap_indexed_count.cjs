// Reads a recording with the MCAP authors' TypeScript indexed reader (@mcap/core's
// McapIndexedReader: the reader Foxglove and Lichtblick use), through its summary and chunk
// indexes only, and prints the chunk count and every channel's message count as JSON; with a
// second argument T (ns), also the log time of the first /swarmloc/frame message at or after T,
// found by seeking. Used by tests/test_recording_index.py (an independent reader of our files).
const { McapIndexedReader } = require("@mcap/core");
const { decompress } = require("fzstd");
const lz4 = require("lz4js");
const fs = require("node:fs/promises");

async function main() {
  const handle = await fs.open(process.argv[2], "r");
  const size = (await handle.stat()).size;
  const readable = {
    size: async () => BigInt(size),
    read: async (offset, length) => {
      const buf = new Uint8Array(Number(length));
      await handle.read(buf, 0, Number(length), Number(offset));
      return buf;
    },
  };
  const reader = await McapIndexedReader.Initialize({
    readable,
    decompressHandlers: {
      zstd: (data, decompressedSize) => decompress(data, new Uint8Array(Number(decompressedSize))),
      lz4: (data) => Uint8Array.from(lz4.decompress(data)),
    },
  });
  const counts = {};
  for await (const msg of reader.readMessages()) {
    const topic = reader.channelsById.get(msg.channelId).topic;
    counts[topic] = (counts[topic] ?? 0) + 1;
  }
  const out = { chunks: reader.chunkIndexes.length, counts };
  if (process.argv[3] !== undefined) {
    for await (const msg of reader.readMessages({ topics: ["/swarmloc/frame"], startTime: BigInt(process.argv[3]) })) {
      out.first_frame_ns = msg.logTime.toString();
      break;
    }
  }
  await handle.close();
  console.log(JSON.stringify(out));
}

main().catch((err) => { console.error(err); process.exit(1); });
