"""An unknown --source kind or source key names every accepted one (from the one table of
sources and the participant's parameters, so a list cannot leave one out) and the closest
one when it looks like a typo, in `stream` and in `trial`."""

from __future__ import annotations

import dataclasses
import os
import re
import subprocess
import sys

import pytest
from conftest import REPO_ROOT

from graspguide.participant.model import ParticipantParams, VirtualParticipant
from graspguide.sources import poses as sources
from graspguide.sources import trial_sources
from graspguide.sources.source_spec import open_source

SCENE3 = os.path.join(REPO_ROOT, "tools", "examples", "scene_paper_3.toml")
PROTOCOL = os.path.join(REPO_ROOT, "protocols", "paper.toml")


def _run(args) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    cmd = [sys.executable, "-m", "graspguide", *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=60, env=env, cwd=REPO_ROOT)


def _stream(source: str) -> subprocess.CompletedProcess:
    # the source is refused before the device is opened: a port that is not there is fine
    return _run(
        ["stream", "--port", "sim", "--scene", SCENE3, "--wrench", "0.3,-1.2,-0.8"]
        + ["--source", source]
    )


def _trial(source: str, tmp_path) -> subprocess.CompletedProcess:
    return _run(
        ["trial", "--protocol", PROTOCOL, "--participant", "U1", "--port", "sim"]
        + ["--source", source, "--out", str(tmp_path)]
    )


def _listed(message: str) -> set[str]:
    return set(re.findall(r'"([^"]+)"', message.split("accepted: ", 1)[1].splitlines()[0]))


@pytest.mark.parametrize("command", ["stream", "trial"])
def test_an_unknown_source_kind_lists_every_kind(command, tmp_path):
    done = _stream("vicon") if command == "stream" else _trial("vicon", tmp_path)
    assert done.returncode == 2, done.stderr
    assert _listed(done.stderr) == set(sources.SOURCE_KINDS), done.stderr
    assert "participant" in done.stderr
    # vicon is a tracker: the message says where it goes
    assert "--tracker vicon" in done.stderr, done.stderr


@pytest.mark.parametrize("command", ["stream", "trial"])
def test_a_misspelt_source_kind_gets_a_did_you_mean(command, tmp_path):
    done = _stream("particpant") if command == "stream" else _trial("particpant", tmp_path)
    assert done.returncode == 2, done.stderr
    assert 'did you mean "participant"?' in done.stderr, done.stderr


def test_a_misspelt_participant_key_in_stream_lists_seed_and_suggests_it():
    done = _stream("participant:sed=2")
    assert done.returncode == 2, done.stderr
    assert 'did you mean "seed"?' in done.stderr, done.stderr
    listed = _listed(done.stderr)
    assert listed == set(trial_sources.participant_keys(seed=True)), done.stderr
    assert "seed" in listed and "fingers" in listed


def test_a_misspelt_participant_key_in_trial_suggests_the_parameter(tmp_path):
    done = _trial("participant:reaction_tme_s=0.3", tmp_path)
    assert done.returncode == 2, done.stderr
    assert 'did you mean "reaction_time_s"?' in done.stderr, done.stderr
    assert _listed(done.stderr) == set(trial_sources.participant_keys(seed=False))


def test_a_misspelt_synthetic_option_gets_a_did_you_mean():
    with pytest.raises(sources.SourceError, match='did you mean "rate"'):
        open_source("synthetic:rat=100")


def test_the_participant_keys_are_the_ones_the_participant_takes():
    """The table the messages list: every key of it is accepted (seed by stream)."""
    names = [f.name for f in dataclasses.fields(ParticipantParams)]
    keys = trial_sources.participant_keys(seed=False)
    assert set(names) <= set(keys)
    for key in keys:
        value = "3" if key == "fingers" else str(getattr(ParticipantParams(), key))
        VirtualParticipant.from_spec(f"{key}={value}", 0)
    assert trial_sources.participant_keys(seed=True) == ["seed", *keys]
