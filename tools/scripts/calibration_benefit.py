#!/usr/bin/env python3
"""What a per-finger calibration does for a virtual participant whose fingers differ
(docs/calibration.md). SIMULATED: virtual participants, never human data.

Three conditions, the same protocol and participants U1..UP on --port sim:

* uniform:    `--source participant` (every motor felt alike, the default model);
* fingers:    `--source participant:fingers=N` (participant Ui feels with the fingers of
  the calibration's simulated person N = i: per-finger threshold and magnitude), the
  paper's mapping on the device;
* calibrated: the same participant, after `graspguide calibrate --source
  participant:seed=N` (the same person N) wrote OUT/calibrated/PID/calibration.json,
  which `graspguide trial` sends to the device before the first trial;
* truth (a diagnostic): the same, but the file's calibration replaced by the observer's
  true values (floor = its 50 % threshold rounded, gain = magnitude_ref / magnitude_i,
  every gain then scaled by calibrate's headroom factor):
  what a perfect measurement would buy, to tell the model's limits from the procedure's.

    python tools/scripts/calibration_benefit.py [--participants P] [--jobs J]
        [--protocol FILE] [--out DIR] [--json FILE]

Studies go to OUT/{uniform,fingers,calibrated,truth} (default logs/calibration-benefit); they
resume like the demo, so running again only tabulates again.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
from collections.abc import Sequence
from typing import Any

from graspguide.analysis.outcome_summary import format_outcome, outcome_summary
from graspguide.protocol.study_protocol import draw_wrenches, load_protocol
from graspguide.records.storage import read_jsonl
from graspguide.study.jobs import TrialJob, default_out, default_protocol, run_trial_jobs

CONDITIONS = ("uniform", "fingers", "calibrated", "truth")
CAL_FINGERS = "thumb,index,middle,palm"  # protocols/paper.toml's k = 4 uses the palm


def person(pid: str) -> int:
    """The simulated person N of participant Ui: N = i."""
    return int(pid[1:])


def source(condition: str, pid: str) -> str:
    return "participant" if condition == "uniform" else f"participant:fingers={person(pid)}"


@dataclasses.dataclass
class CalibrateJob(TrialJob):
    """`graspguide calibrate` for one participant, run by the same pool as the trials."""

    headroom: bool = True

    def command(self) -> list[str]:
        return [
            sys.executable,
            "-m",
            "graspguide",
            "calibrate",
            "--port",
            "sim",
            "--participant",
            self.participant,
            "--out",
            self.study_dir,
            "--fingers",
            CAL_FINGERS,
            "--source",
            f"participant:seed={person(self.participant)}",
        ] + ([] if self.headroom else ["--no-headroom"])


def write_true_calibration(measured: str, path: str, n: int, headroom: bool = True) -> None:
    """The measured calibration file with its calibration replaced by person ``n``'s
    truth (the index finger is calibrate's default reference)."""
    from graspguide.calibration.session import headroom_scale
    from graspguide.calibration.virtual_observer import VirtualObserver
    from graspguide.core.motor_calibration import FINGER_NAMES

    obs = VirtualObserver(seed=n)
    with open(measured, encoding="utf-8") as f:
        data = json.load(f)
    floors = [int(round(obs.fingers[f].threshold_pwm)) for f in FINGER_NAMES]
    gains = [obs.true_gain(f, "index") for f in FINGER_NAMES]
    # The same headroom as calibrate's default: one factor for every gain, none clips.
    scale = headroom_scale(floors, gains) if headroom else 1.0
    data["calibration"] = {"pwm_floor": floors, "gain": [g * scale for g in gains]}
    data["warnings"] = list(data.get("warnings", [])) + [
        "calibration replaced by the virtual observer's true values (calibration_benefit.py)"
    ]
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w", encoding="utf-8") as f:
        json.dump(data, f, indent=2)


def saturated_c_trials(out: str, pids: Sequence[str], protocol_path: str) -> dict[str, Any]:
    """Per calibrated condition: of the mode C trials (each participant x wrench x policy
    x k once: a mode C PWM does not depend on the pose), how many drive a motor at 255 --
    where a gain above 1 clips the relative strengths that mode C is read from."""
    import numpy as np

    from graspguide.calibration.calibration_file import load_participant_calibration
    from graspguide.core import _core
    from graspguide.core.reference import pwm_from_levels

    protocol = load_protocol(protocol_path)
    wrenches = [list(w.wrench) for w in draw_wrenches(protocol)]
    res: dict[str, Any] = {}
    for cond in ("calibrated", "truth"):
        n = sat = 0
        for pid in pids:
            cal = load_participant_calibration(os.path.join(out, cond), pid)
            for contacts in protocol.hands.values():
                for policy in ("F", "Fperp"):
                    for w in wrenches:
                        r = _core.solve(
                            contacts=[list(c) for c in contacts],
                            wrench=w,
                            policy=policy,
                            mode="C",
                            constraints="paper",
                            orientation=list(protocol.start_quat),
                            y_axis=list(protocol.y_axis),
                        )
                        if r["status"] != "ok":
                            continue
                        n += 1
                        pwm = pwm_from_levels(np.asarray(r["levels"]), "C", 0.0, cal)
                        sat += any(v >= 255 for v in pwm)
        res[cond] = {"mode_c_trials": n, "with_a_motor_at_255": sat}
    return res


def _rows(study_dir: str, pids: Sequence[str]) -> list[dict[str, Any]]:
    out = []
    for pid in pids:
        for r in read_jsonl(os.path.join(study_dir, pid, "trials.jsonl")).records:
            if not r.get("familiarization"):
                out.append(r)
    return out


def _mode(r: dict[str, Any]) -> str:
    return str(r["modality"]).rsplit("+", 1)[-1]


def tabulate(out: str, pids: Sequence[str]) -> dict[str, Any]:
    res: dict[str, Any] = {"simulated": True, "participants": list(pids), "conditions": {}}
    for cond in CONDITIONS:
        rows = _rows(os.path.join(out, cond), pids)
        res["conditions"][cond] = {
            "source": [source(cond, p) for p in pids],
            **{
                f"k={k} {m}": outcome_summary([r for r in rows if r["k"] == k and _mode(r) == m])
                for k in (3, 4)
                for m in ("C", "V")
            },
            **{m: outcome_summary([r for r in rows if _mode(r) == m]) for m in ("C", "V")},
        }
    return res


def format_table(res: dict[str, Any]) -> str:
    lines = [
        f"SIMULATED: virtual participants {', '.join(res['participants'])} (fingers of "
        "person N = i for Ui); main trials; successes, rate, mean completion (a failure "
        "counts as the timeout)",
        f"{'':<8} " + " ".join(f"{c:>24}" for c in CONDITIONS),
    ]
    for key in ("C", "V", "k=3 C", "k=3 V", "k=4 C", "k=4 V"):
        lines.append(
            f"{key:<8} " + " ".join(format_outcome(res["conditions"][c][key]) for c in CONDITIONS)
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--participants", type=int, default=8, metavar="P")
    p.add_argument("--protocol", default=None, help="default protocols/paper.toml")
    p.add_argument("--out", default=None, help="default logs/calibration-benefit")
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--json", default=None, metavar="FILE", help="also write the figures here")
    p.add_argument(
        "--no-headroom",
        action="store_true",
        help="calibrate --no-headroom: the matched gains as they are, strong cues may clip",
    )
    a = p.parse_args(argv)
    if not 1 <= a.participants <= 256:
        p.error(f"--participants must be in 1..256, got {a.participants}")
    if a.jobs < 1:
        p.error(f"--jobs must be at least 1, got {a.jobs}")
    protocol = a.protocol or default_protocol()
    load_protocol(protocol)  # a bad file fails here, with its message
    out = a.out or default_out("calibration-benefit")
    pids = [f"U{i}" for i in range(1, a.participants + 1)]
    logs = os.path.join(out, "logs")
    cal_dir = os.path.join(out, "calibrated")

    def on_exit(job: TrialJob, rc: int) -> None:
        print(f"{job.tag} {job.participant}: exit {rc} ({job.log})", file=sys.stderr, flush=True)

    calibrations: list[TrialJob] = [
        CalibrateJob(
            protocol,
            cal_dir,
            pid,
            "",
            os.path.join(logs, f"calibrate-{pid}.log"),
            headroom=not a.no_headroom,
        )
        for pid in pids
        if not os.path.exists(os.path.join(cal_dir, pid, "calibration.json"))
    ]
    for job in calibrations:
        job.tag = "calibrate"
    trials: list[TrialJob] = [
        TrialJob(
            protocol,
            os.path.join(out, cond),
            pid,
            source(cond, pid),
            os.path.join(logs, f"{cond}-{pid}.log"),
            tag=cond,
        )
        for cond in CONDITIONS
        for pid in pids
    ]
    for batch in (calibrations, trials):
        if batch is trials:
            for pid in pids:
                truth = os.path.join(out, "truth", pid, "calibration.json")
                if not os.path.exists(truth):
                    measured = os.path.join(cal_dir, pid, "calibration.json")
                    write_true_calibration(measured, truth, person(pid), not a.no_headroom)
        interrupted, failed = run_trial_jobs(batch, a.jobs, on_exit)
        if interrupted:
            print("interrupted; run again to resume", file=sys.stderr)
            return 130
        if failed:
            print(
                "failed: " + ", ".join(f"{j.tag} {j.participant} ({j.log})" for j, _ in failed),
                file=sys.stderr,
            )
            return 1
    res = tabulate(out, pids)
    res["saturation"] = saturated_c_trials(out, pids, protocol)
    print(format_table(res))
    for cond, v in res["saturation"].items():
        print(
            f"{cond}: {v['with_a_motor_at_255']}/{v['mode_c_trials']} mode C trials drive a "
            "motor at PWM 255 (clipped relative strengths)"
        )
    if a.json:
        with open(a.json, "w", encoding="utf-8") as f:
            json.dump(res, f, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
