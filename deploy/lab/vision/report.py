"""The report of seed 004's experiments: ``docs/vision/README.md`` with its figures.

:func:`write_report` writes the table of measured runs next to the paper's claims
(:data:`PAPER_CLAIMS`; the paper shows one or two trials per experiment and gives no numbers),
trajectory and summary figures, the detection accuracy and the command that regenerates it;
:func:`summary_table` is its table of runs. :data:`TEMPLATE` is the vision template of
``swarmloc report``: the first group of the results (``deploy/experiments/vision.toml``:
``main``) is the main table, every other group a sensitivity table.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from swarmloc.deploy.lab.vision.experiment import (
    _TEXT_COLUMNS,
    COLUMNS,
    detection_table,
    summarize,
    write_csv,
)
from swarmloc.deploy.lab.vision.runner import EXPERIMENTS, load_vision_scenario, run_vision
from swarmloc.world.vision.camera import OBJECT_KINDS

# -- the report ---------------------------------------------------------------------------------

#: Seed 004 §IV's claims, one per (experiment, aspect). The paper shows one or two trials per
#: experiment in figures; it gives no numbers.
PAPER_CLAIMS = {
    "vision-exp1": [
        (
            "collisions without sharing",
            "§IV-A, Fig. 6a",
            (
                '"the two AIBOs crash in the middle of the experiment, and they go on crashing till '
                'they catch the ball"'
            ),
        ),
        (
            "collisions with sharing",
            "§IV-A, Fig. 6b",
            (
                '"they correctly estimate their position. Thus they avoid crashing and finally they '
                'catch the ball from opposite sides"'
            ),
        ),
    ],
    "vision-exp2": [
        (
            "goals and collisions with sharing",
            "§IV-B, Fig. 7a/7b",
            (
                '"they correctly estimate where they are to avoid crash and ... they catch the correct '
                'objective", in both assignments'
            ),
        ),
    ],
    "vision-exp3": [
        (
            "the robot that cannot see the ball",
            "§IV-C, Fig. 8a/8b",
            (
                '"they establish their goals correctly. This shows that they have correctly shared '
                'information about the estimated position of the ball"; no crash'
            ),
        ),
    ],
}


def _pct(k: int, n: int) -> str:
    return f"{k}/{n} ({100.0 * k / n:.0f} %)" if n else "-"


def _fmt(value, spec=".2f", unit="") -> str:
    return "-" if value is None else f"{format(value, spec)}{unit}"


def _ours(summary: list[dict], scenario: str, aspect: str) -> tuple[str, str]:
    by = {s["sharing"]: s for s in summary if s["scenario"] == scenario}
    on, off = by.get(True), by.get(False)
    if aspect == "collisions without sharing" and off:
        return (
            (
                f"collided in {_pct(off['runs_with_collision'], off['runs'])} runs without sharing, "
                f"in contact {_fmt(off['contact_s_median'], '.1f')} s (median); both still reach "
                f"the ball in {_pct(off['all_reached'], off['runs'])}"
            ),
            "agrees" if off["runs_with_collision"] >= 0.8 * off["runs"] else "differs",
        )
    if aspect == "collisions with sharing" and on:
        return (
            (
                f"collided in {_pct(on['runs_with_collision'], on['runs'])} runs with sharing; both "
                f"reached the ball in {_pct(on['all_reached'], on['runs'])}, median "
                f"{_fmt(on['all_reached_s_median'], '.1f')} s; teammate error "
                f"{_fmt(on['teammate_err_median_m'], '.3f')} m (median of run medians). They "
                "arrive side by side, not from opposite sides"
            ),
            "agrees (collisions)" if on["runs_with_collision"] == 0 else "differs",
        )
    if aspect == "goals and collisions with sharing" and on:
        text = (
            f"goals right in {_pct(on['goals_correct'], on['runs'])} runs ({on['variants']}), "
            f"collided in {on['runs_with_collision']}, both reached their goal in "
            f"{_pct(on['all_reached'], on['runs'])}"
        )
        if off:
            text += (
                f"; without sharing: goals right in {_pct(off['goals_correct'], off['runs'])}, "
                f"collided in {_pct(off['runs_with_collision'], off['runs'])}"
            )
        ok = on["goals_correct"] == on["runs"] and on["runs_with_collision"] == 0
        return text, "agrees" if ok else "differs"
    if aspect == "the robot that cannot see the ball" and on:
        text = (
            f"with sharing the blind robot placed the ball in "
            f"{_pct(on['blind_ball_runs'], on['runs'])} runs (first after "
            f"{_fmt(on['blind_ball_first_s'], '.1f')} s, relayed-ball error "
            f"{_fmt(on['blind_relayed_ball_err_median_m'], '.3f')} m), goals right in "
            f"{_pct(on['goals_correct'], on['runs'])} ({on['variants']}), collided in "
            f"{on['runs_with_collision']}, both reached in {_pct(on['all_reached'], on['runs'])}"
        )
        if off:
            text += (
                f"; without sharing: goals right in {_pct(off['goals_correct'], off['runs'])}, "
                f"collided in {_pct(off['runs_with_collision'], off['runs'])}"
            )
        ok = on["goals_correct"] == on["runs"] and on["runs_with_collision"] == 0
        return text, "agrees" if ok else "differs"
    return "not measured", "-"


def summary_table(summary: list[dict]) -> str:
    header = (
        "| scenario | sharing | runs | runs with a robot-robot collision | collisions per run "
        "(mean) | contact s (median) | runs touching the obstacle | goals right | both reached "
        "| time to both reached s (median) | teammate error m (median / p90) | teammate known "
        "| ball error m (median) | blind robot: ball known in runs, first at s, relayed error m |"
    )
    lines = [header, "|" + "---|" * 14]
    for s in summary:
        blind = "-"
        if s["scenario"] == "vision-exp3":
            blind = (
                f"{s['blind_ball_runs']}/{s['runs']}, {_fmt(s['blind_ball_first_s'], '.1f')}, "
                f"{_fmt(s['blind_relayed_ball_err_median_m'], '.3f')}"
            )
        lines.append(
            f"| {s['scenario']} | {'on' if s['sharing'] else 'off'} | {s['runs']} | "
            f"{s['runs_with_collision']} | {s['collisions_mean']:.2f} | "
            f"{_fmt(s['contact_s_median'], '.1f')} | {s['obstacle_collision_runs']} | "
            f"{s['goals_correct']} | {s['all_reached']} | {_fmt(s['all_reached_s_median'], '.1f')} | "
            f"{_fmt(s['teammate_err_median_m'], '.3f')} / {_fmt(s['teammate_err_p90_m'], '.3f')} | "
            f"{_fmt(s['teammate_known_fraction'], '.2f')} | {_fmt(s['ball_err_median_m'], '.3f')} | "
            f"{blind} |"
        )
    return "\n".join(lines)


def _trajectory_figure(records: dict, path: Path) -> None:
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle

    names = [n for n in EXPERIMENTS if any(k[0] == n for k in records)]
    fig = Figure(figsize=(11, 3.0 * len(names)), layout="constrained")
    axes = fig.subplots(len(names), 2, squeeze=False)
    colours = ("tab:blue", "black")
    for row, name in enumerate(names):
        for col, sharing in enumerate((False, True)):
            ax = axes[row][col]
            key = (name, sharing)
            if key not in records:
                ax.set_visible(False)
                continue
            seed, metrics, rec = records[key]
            poses = np.array(rec.poses)
            for o in rec.layout.objects:
                colour = {"ball": "deeppink", "obstacle": "darkorange"}.get(o.kind, "grey")
                ax.add_patch(Circle((o.x_m, o.y_m), OBJECT_KINDS[o.kind].radius_m, color=colour))
            tm = np.array(rec.teammate_world).reshape(len(poses), -1, 2)
            ball = np.array(rec.ball_world).reshape(len(poses), -1, 2)
            for i in range(poses.shape[1]):
                chosen = metrics["goals"].split("/")[i]
                label = f"robot {i}" + (" (white, blind)" if rec.layout.blind == i else "")
                label += f": should take the {rec.layout.goals[i]}, took the {chosen}"
                ax.plot(poses[:, i, 0], poses[:, i, 1], color=colours[i], lw=1.5, label=label)
                ax.add_patch(Circle(poses[0, i, :2], 0.1, fill=False, color=colours[i], ls="--"))
                ax.add_patch(Circle(poses[-1, i, :2], 0.1, fill=False, color=colours[i]))
                ax.plot(tm[::3, i, 0], tm[::3, i, 1], ".", ms=2.5, color=colours[1 - i], alpha=0.5)
                if rec.layout.blind == i:
                    ax.plot(
                        ball[::3, i, 0],
                        ball[::3, i, 1],
                        "x",
                        ms=3,
                        color="deeppink",
                        alpha=0.6,
                        label="white's ball estimate",
                    )
            for x, y in rec.collision_points:
                ax.plot(x, y, "r*", ms=12)
            ax.set_aspect("equal")
            ax.set_title(
                f"{name}, sharing {'on' if sharing else 'off'} (seed {seed}): "
                f"{metrics['collisions']} collision(s), goals "
                f"{'right' if metrics['goals_correct'] else 'wrong'}",
                fontsize=9,
            )
            ax.set_xlabel("x (m)")
            ax.set_ylabel("y (m)")
            ax.legend(fontsize=7, loc="best")
            ax.grid(alpha=0.3)
    fig.savefig(path, dpi=100, metadata={"Software": None})


def _summary_figure(summary: list[dict], path: Path) -> None:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10, 3.4), layout="constrained")
    axes = fig.subplots(1, 3)
    names = [n for n in EXPERIMENTS if any(s["scenario"] == n for s in summary)]
    x = np.arange(len(names))
    for ax, (key, title) in zip(
        axes,
        (
            ("runs_with_collision", "runs with a robot-robot collision"),
            ("goals_correct", "runs with the right goals"),
            ("all_reached", "runs where both reach their goal"),
        ),
    ):
        for k, sharing in enumerate((False, True)):
            vals = []
            for n in names:
                s = next(
                    (s for s in summary if s["scenario"] == n and s["sharing"] == sharing), None
                )
                vals.append(100.0 * s[key] / s["runs"] if s else np.nan)
            ax.bar(
                x + (k - 0.5) * 0.38,
                vals,
                width=0.38,
                label=f"sharing {'on' if sharing else 'off'}",
                color="tab:green" if sharing else "tab:grey",
            )
        ax.set_xticks(x, [n.replace("vision-", "") for n in names])
        ax.set_ylim(0, 125)
        ax.set_yticks(range(0, 101, 20))
        ax.set_ylabel("% of runs")
        ax.set_title(title, fontsize=9)
        ax.legend(fontsize=7, loc="upper center", ncol=2)
    fig.savefig(path, dpi=100, metadata={"Software": None})


def write_report(
    out_dir: str | Path,
    rows: list[dict],
    detection: dict | None,
    commands: list[str],
    timing: str = "",
    figure_seeds: dict | None = None,
    sensitivity: list[tuple[str, str, list[dict]]] = (),
) -> Path:
    """``README.md``, ``results.csv`` and the figures in ``out_dir``; returns the README path.

    ``figure_seeds``: the seed whose trajectories are drawn, per scenario (default: the first
    seed of the rows, for experiment 3 the first of variant "a", where the blind robot must
    walk around the obstacle). ``sensitivity``: ``(what, how, rows)`` of extra runs, each
    shown as its own table (``how``: a line saying how they were run).
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    write_csv(rows, out / "results.csv")
    summary = summarize(rows)
    figure_seeds = dict(figure_seeds or {})
    records = {}
    for name in sorted({r["scenario"] for r in rows}):
        seeds = [r["seed"] for r in rows if r["scenario"] == name]
        if name not in figure_seeds:
            pick = [r["seed"] for r in rows if r["scenario"] == name and r["variant"] == "a"]
            figure_seeds[name] = (pick or seeds)[0]
        scenario = load_vision_scenario(name)
        for sharing in sorted({r["sharing"] for r in rows if r["scenario"] == name}):
            metrics, rec = run_vision(scenario, figure_seeds[name], sharing, record=True)
            records[(name, sharing)] = (figure_seeds[name], metrics, rec)
    _trajectory_figure(records, out / "vision_trajectories.png")
    _summary_figure(summary, out / "vision_summary.png")
    seeds = sorted({r["seed"] for r in rows})
    lines = [
        "# Seed 004: cooperative localization from shared colour blobs (vision robots)",
        "",
        (
            "Two simulated legged robots with one camera each (pinhole, f = 190 px, 208 x 160 px, noise "
            "and lighting variation, JPEG frames) detect colour blobs with OpenCV, share their "
            'detections ("Telepathy"), locate each other by stereo (eq. 1) and the law of cosines '
            "(eq. 2) from objects seen in common, and walk with a potential field (eq. 3-5) to the goals "
            "of seed 004 §IV. Each run draws its own layout (mirror image and variant a/b of the "
            "paper's figures at random), checked by rendering: each robot sees at the start what the "
            "paper says it sees."
        ),
        "",
        "## Regenerate",
        "",
        "```sh",
        *commands,
        "```",
        "",
        (
            f"Seeds {seeds[0]}-{seeds[-1]} ({len(seeds)} runs per scenario and sharing mode); run "
            "seed s draws its layout from `default_rng([s, 2])`, the world from `[s, 0]`, robot i's "
            "brain from `[s, 1, i]`. Scenarios: `deploy/scenarios/vision/vision-exp{1,2,3}.toml`."
        ),
        "",
        "## The paper's claims and ours",
        "",
        (
            "The paper shows one or two trials per experiment (Fig. 6-8) and gives no numbers; ours are "
            "counts over the seeded runs below."
        ),
        "",
        "| experiment | claim | source | paper | ours | verdict |",
        "|---|---|---|---|---|---|",
    ]
    for name in EXPERIMENTS:
        if not any(s["scenario"] == name for s in summary):
            continue
        for aspect, source, paper in PAPER_CLAIMS[name]:
            ours, verdict = _ours(summary, name, aspect)
            lines.append(f"| {name} | {aspect} | {source} | {paper} | {ours} | {verdict} |")
    lines += [
        "",
        "## All measurements",
        "",
        (
            "Per scenario and sharing mode. A collision is a pair of bodies coming into contact; "
            '"goals right": every robot chose the goal the rule of §IV gives on the true start '
            'positions (the robot nearest the obstacle takes it); "both reached": each robot\'s centre '
            "came within body + goal radius + 10 cm of its right goal within 40 s; errors are each "
            "run's median over the ticks where the robot had an estimate, then the median over runs "
            '(p90: the median over runs of each run\'s 90th percentile); "teammate known": fraction '
            "of robot-ticks with a teammate estimate. Rejected images and payloads: "
            f"{sum(s['bad_images'] for s in summary)} and {sum(s['bad_payloads'] for s in summary)} "
            "(none are injected in these runs). Raw rows: `results.csv`."
        ),
        "",
        summary_table(summary),
        "",
        "CPU per run (mean): "
        + ", ".join(
            f"{s['scenario']} {'on' if s['sharing'] else 'off'} {s['cpu_s_mean']:.2f} s"
            for s in summary
        )
        + ".",
        "",
        "![summary](vision_summary.png)",
        "",
        (
            "Trajectories of one run per experiment (left: sharing off, right: on). Lines: true paths "
            "(dashed circle: start, solid: end); dots: each robot's estimate of the other, drawn in "
            "the colour of the robot estimated; crosses: the blind robot's estimate of the ball; red "
            "stars: collisions."
        ),
        "",
        "![trajectories](vision_trajectories.png)",
        "",
    ]
    if sensitivity:
        lines += ["## Sensitivity", ""]
        for what, how, sens_rows in sensitivity:
            lines += [
                f"{what}:",
                "",
                how,
                "",
                summary_table(summarize(sens_rows)),
                "",
            ]
    if detection is not None:
        lines += [
            "## Blob detection against ground truth",
            "",
            (
                "Rendered frames with the default noise (sigma 6 grey levels) and lighting (gain "
                "0.7-1.3), JPEG-encoded and decoded as the agent receives them, then `detect_blobs` and "
                "the agent's shape check (`detections_from_blobs`). Random camera poses; the object wholly "
                'in the image. "Blob found": any blob of the object\'s colour; "used": a detection '
                "the agent keeps; errors are those of the used detections (bearing in the camera "
                "frame, distance relative). Occlusion: an orange robot halfway hides part of the "
                "object; the agent drops a blob whose shape shows it is partly hidden, rather than "
                "trusting its too-small size."
            ),
            "",
            detection_table(detection),
            "",
        ]
        if timing:
            lines += [timing, ""]
    lines += [
        "## Model notes and limits",
        "",
        (
            "- The robots start side by side and parallel, as in §IV; each brain assumes that initial "
            "relative heading (0) and follows it with both robots' odometry (shared in the payload). "
            "Start headings are jittered by up to ±0.03 rad, so that assumption is off by up to "
            "0.06 rad."
        ),
        (
            "- Odometry is the commanded walk; the true motion has 5 % Gaussian errors per tick on "
            "translation and rotation plus a heading drift (0.01 rad/√s); being pushed in a "
            "collision is not in the odometry."
        ),
        (
            "- Gains of eq. 3-5 are not in the paper: k1 = 0.5 /s, obstacle k2 = 0.02 m³/s within "
            "0.5 m, teammate k2 = 0.02 m³/s within 0.6 m, speed 0.3 m/s; a detour force (not in the "
            "paper) gets a robot around an obstacle that stands between it and its goal."
        ),
        (
            "- The simulated images are clean compared with an Aibo's: pure colours, no blur, no "
            "shadows; so the size-based distances (a few % error) and the teammate estimates "
            "(a few cm) are better than the paper's robots would get."
        ),
        (
            "- A blob is used only if its shape is that of a whole object (within 15 %): a partly "
            "hidden ball or robot would look farther than it is. The price: about half of the "
            "slightly hidden objects (75-100 % visible) are dropped too, and a sliver of a mostly "
            "hidden ball is occasionally kept (a few pixels cannot tell a sliver from a far ball)."
        ),
        (
            "- The relative heading of two robots with one object in common comes from the "
            "parallel start and their odometry (see Sensitivity for what a wrong start does); "
            "two objects in common give it directly (Fig. 2), as the option "
            '`agent.relative_heading = "objects"` does.'
        ),
        "- Goals are decided once; the ball does not move.",
        "",
    ]
    readme = out / "README.md"
    readme.write_text("\n".join(lines))
    return readme


# -- the template of `swarmloc report` ----------------------------------------------------------

_ORDER = {name: i for i, name in enumerate(EXPERIMENTS)}


def _run_order(row: dict):
    return (_ORDER.get(row["scenario"], len(_ORDER)), row["scenario"], not row["sharing"],
            row["seed"])


def report_rows(engine_rows: list[dict]) -> list[dict]:
    """Rows of the engine's vision results as the report takes them (:data:`COLUMNS`:
    ``experiment`` is the scenario's experiment of §IV), in the order scenario, sharing on
    first, seed."""
    setup: dict[str, int] = {}
    out = []
    for r in engine_rows:
        name = r["scenario"]
        if name not in setup:
            setup[name] = load_vision_scenario(name).setup.experiment
        out.append({**{k: r.get(k) for k in COLUMNS}, "experiment": setup[name]})
    return sorted(out, key=_run_order)


def _group_how(group, runs: int) -> str:
    fixed = ", ".join(f"`{k} = {json.dumps(v)}`" for k, v in group.set) or "the scenarios as shipped"
    return f"Group `{group.name}` of the spec: {fixed}; {runs} runs per scenario."


def write_from_args(paths: list[Path], args) -> Path:
    """The vision template of ``swarmloc report``: main table from the first group, sensitivity
    tables from the others (described by the spec's groups), the detection accuracy
    (``--detection-n`` placements per bin) and the cost per frame measured here."""
    import cv2

    from swarmloc.config import ConfigError
    from swarmloc.deploy.lab.experiment import load_spec
    from swarmloc.deploy.lab.vision.experiment import detection_accuracy, frame_costs, read_csv

    rows = []
    for path in paths:
        rows += read_csv(path, text_columns=_TEXT_COLUMNS + ("experiment",))
    if not rows:
        raise ConfigError(f"{', '.join(map(str, paths))}: no rows to report")
    missing = [c for c in ("group", "scenario", "sharing", "seed") if c not in rows[0]]
    if missing:
        raise ConfigError(f"{paths[0]}: not a vision results file (no {', '.join(missing)})")
    experiments = sorted({r["experiment"] for r in rows})
    spec = None
    try:
        spec = load_spec(args.spec or experiments[0])
    except ConfigError:
        if args.spec:
            raise
    groups = list(dict.fromkeys(r["group"] for r in rows))
    if spec is not None:
        groups = [g.name for g in spec.group if g.name in groups] + [
            g for g in groups if g not in {x.name for x in spec.group}]
    by_group = {g: [r for r in rows if r["group"] == g] for g in groups}
    main = report_rows(by_group[groups[0]])
    sensitivity = []
    for name in groups[1:]:
        group = next((g for g in spec.group if g.name == name), None) if spec else None
        sens = report_rows(by_group[name])
        runs = len({r["seed"] for r in sens})
        what = (group.description if group is not None and group.description else
                f"group {name}")
        how = _group_how(group, runs) if group is not None else f"Group `{name}`; {runs} runs."
        sensitivity.append((what, how, sens))
    out = Path(args.out) if args.out else Path("docs/vision")
    runs = len({r["seed"] for r in main})
    fewer = f" --replications {runs}" if spec is not None and runs != spec.replications else ""
    commands = [args.regen_command] if args.regen_command else [
        f"swarmloc experiment {experiments[0]}{fewer} --out {paths[0]}",
        "swarmloc report " + " ".join(map(str, paths)) + f" --out {out}",
    ]
    commands.append("python benchmarks/bench_vision_detection.py   # detection table and timing")
    cv2.setNumThreads(1)  # the frame timing below is per core
    detection = detection_accuracy(args.detection_n) if args.detection_n > 0 else None
    render_ms, path_ms = frame_costs()
    timing = (
        f"Cost per frame (median CPU of 500 frames, 6 objects, this machine): render + detect "
        f"{render_ms:.2f} ms (target 5 ms); render + JPEG encode + decode + detect + the "
        f"agent's detections {path_ms:.2f} ms."
    )
    return write_report(out, main, detection, commands, timing=timing, sensitivity=sensitivity)


def _template():
    from swarmloc.deploy.lab.report import ReportTemplate

    return ReportTemplate("vision", frozenset({"experiment", "group", "sharing", "goals_correct",
                                               "collisions"}), write_from_args)


#: This family's template of ``swarmloc report`` (:data:`swarmloc.deploy.lab.report.TEMPLATES`).
TEMPLATE = _template()
