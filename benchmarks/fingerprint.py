"""A fingerprint of seeded batch runs: run it before and after a change meant to be
behaviour-preserving (an optimisation, a refactor) and compare the two hashes.

It hashes the metrics, true final poses and dead-reckoned poses of ES1 runs (200 s) for several
strategies and seeds. Usage: ``python benchmarks/fingerprint.py [--variant NAME]``; with
``--variant v0-defaults`` (the e-puck defaults before issue 18) it prints what main printed
before issue 18 changed the defaults (950bdf53b1cb8f51).
"""

from __future__ import annotations

import hashlib
import json


def main(argv: list[str] | None = None) -> int:
    import argparse

    from swarmloc.deploy.lab.epuck.batch import run_batch
    from swarmloc.deploy.scenario import load_scenario, variant_overrides

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--variant", default=None, help="a named variant of the defaults (e.g. v0-defaults)")
    variant = variant_overrides(p.parse_args(argv).variant)
    digest = hashlib.sha256()
    for strategy in ("SSGIKF", "NC", "DSGIFF", "SSIKF"):
        for seed in (1, 2):
            result = run_batch(load_scenario(
                "ES1", [*variant, f"agent.strategy={strategy}", f"world.seed={seed}", "world.duration_s=200"]
            ))
            digest.update(json.dumps(result.metrics, sort_keys=True).encode())
            digest.update(result.final_pose.tobytes())
            digest.update(result.pose_estimate.tobytes())
    print(digest.hexdigest()[:16])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
