"""A synthetic study folder for the analysis tests, written by a seeded generator.

8 participants, 4 modalities x 2 contact counts x 12 wrenches, plus familiarization
trials (which an analysis must leave out) and one NASA-TLX record per session. Failures
follow a fixed pattern so the Table I counts are known by hand.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

PIDS = [f"U{i}" for i in range(1, 9)]
ORDER = ["F+C", "Fperp+C", "F+V", "Fperp+V"]
SCALES = ["MD", "TD", "PD", "PE", "EF", "FR"]


def planned_failure(p_idx: int, k: int, modality: str, w: int) -> bool:
    """Constant-intensity trials fail for 2 of the 12 wrenches per participant and
    condition (w + p + k + policy = 0 mod 6); varying-intensity trials never fail."""
    policy, mode = modality.split("+")
    return mode == "C" and (w + p_idx + k + (policy == "Fperp")) % 6 == 0


def make_participant(
    root: Path, p_idx: int, rng, simulated=True, slow=None, modalities=ORDER, familiarization=3
):
    """Write STUDY/<PID>/trials.jsonl and tlx.jsonl; returns (trial records, tlx records).

    slow: {modality: factor} multiplies that participant's times (to make an outlier)."""
    pid = PIDS[p_idx] if p_idx < len(PIDS) else f"U{p_idx + 1}"
    folder = root / pid
    folder.mkdir(parents=True)
    trials, tlx = [], []
    index = 0
    session = 0
    for k in (3, 4):
        for modality in modalities:
            session += 1
            policy, mode = modality.split("+")
            for f in range(familiarization if session == 1 else 0):
                index += 1
                trials.append(
                    dict(
                        participant=pid,
                        simulated=simulated,
                        trial_index=index,
                        session=session,
                        k=k,
                        policy=policy,
                        mode=mode,
                        modality=modality,
                        wrench_id=100 + f,
                        wrench=[0, 0, -1, 0, 0, 0],
                        single_motor=False,
                        success=False,
                        completion_s=90.0,
                        familiarization=True,
                    )
                )
            for w in range(12):
                index += 1
                fail = planned_failure(p_idx, k, modality, w)
                base = 30.0 if mode == "C" else 8.0
                t = 90.0 if fail else float(base * rng.lognormal(0.0, 0.35))
                if slow and modality in slow and not fail:
                    t = min(89.0, t * slow[modality])
                trials.append(
                    dict(
                        participant=pid,
                        simulated=simulated,
                        trial_index=index,
                        session=session,
                        k=k,
                        policy=policy,
                        mode=mode,
                        modality=modality,
                        wrench_id=w,
                        wrench=[float(x) for x in rng.normal(size=6)],
                        single_motor=w < 5,
                        success=not fail,
                        completion_s=t,
                        familiarization=False,
                    )
                )
            scales = {s: int(rng.integers(1, 22)) for s in SCALES}
            tlx.append(
                dict(
                    participant=pid,
                    simulated=simulated,
                    session=session,
                    k=k,
                    modality=modality,
                    mode=mode,
                    scales=scales,
                )
            )
    (folder / "trials.jsonl").write_text("".join(json.dumps(t) + "\n" for t in trials))
    (folder / "tlx.jsonl").write_text("".join(json.dumps(t) + "\n" for t in tlx))
    return trials, tlx


def make_study(root: Path, seed=7, n=8, simulated=True, slow=None):
    rng = np.random.default_rng(seed)
    root.mkdir(parents=True, exist_ok=True)
    all_trials, all_tlx = [], []
    for i in range(n):
        t, q = make_participant(root, i, rng, simulated=simulated, slow=(slow or {}).get(PIDS[i]))
        all_trials += t
        all_tlx += q
    return all_trials, all_tlx
