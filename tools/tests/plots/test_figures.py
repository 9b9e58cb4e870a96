"""What the figures show, read from their matplotlib artists: no line hides another, the
SD bars stay within 0 s and the timeout, every axis says what it is (and that it is
logarithmic), F⊥ is spelled one way, and a simulated run says SIMULATED."""

from __future__ import annotations

import itertools
import json
import shutil
from pathlib import Path

import matplotlib
import pytest

matplotlib.use("Agg", force=True)

from matplotlib.collections import LineCollection  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from graspguide.planning import sweep  # noqa: E402
from graspguide.plots.figures import overview_figure, pyplot, trial_figure  # noqa: E402
from graspguide.plots.run_folder import load_frames, open_run  # noqa: E402

ROOT = Path(__file__).resolve().parents[3]
SWEEP_RESULT = ROOT / "docs" / "perf" / "guidance_sweep.json"
DATA = Path(__file__).parents[1] / "data" / "plot_structure"


def _texts(fig) -> list[str]:
    return [t.get_text() for t in fig.findobj(matplotlib.text.Text) if t.get_text()]


@pytest.fixture(scope="module")
def sweep_fig(tmp_path_factory):
    """The sweep figure as `graspguide sweep` saves it (caught at savefig)."""
    result = json.loads(SWEEP_RESULT.read_text())
    saved = []
    original = Figure.savefig

    def keep(self, *args, **kwargs):
        saved.append(self)
        return original(self, *args, **kwargs)

    Figure.savefig = keep
    try:
        sweep.plot(result, str(tmp_path_factory.mktemp("sweep") / "sweep.png"))
    finally:
        Figure.savefig = original
    (fig,) = saved
    yield fig, result
    pyplot().close(fig)


def _modality_lines(ax, mods):
    from graspguide.core.vocabulary import shown

    by_label = {ln.get_label(): ln for ln in ax.get_lines()}
    return [by_label[shown(m)] for m in mods]


def test_sweep_lines_never_hide_each_other(sweep_fig):
    fig, result = sweep_fig
    mods = result["modalities"]
    for ax in fig.axes:
        if not ax.get_ylabel().startswith("success rate"):
            continue
        lines = _modality_lines(ax, mods)
        looks = {(ln.get_marker(), str(ln.get_linestyle())) for ln in lines}
        assert len(looks) == len(mods), looks  # marker and line style differ
        for a, b in itertools.combinations(lines, 2):
            same = [
                (xa, ya)
                for xa, ya, xb, yb in zip(
                    a.get_xdata(), a.get_ydata(), b.get_xdata(), b.get_ydata()
                )
                if xa == xb and ya == yb
            ]
            assert not same, (a.get_label(), b.get_label(), same)  # 100 %: side by side


def test_sweep_sd_bars_stay_within_zero_and_the_timeout(sweep_fig):
    fig, result = sweep_fig
    timeout = result["timeout_s"]
    bars = 0
    for ax in fig.axes:
        if not ax.get_ylabel().startswith("completion time"):
            continue
        for coll in ax.collections:
            if isinstance(coll, LineCollection):
                for seg in coll.get_segments():
                    ys = seg[:, 1]
                    assert ys.min() >= 0.0 and ys.max() <= timeout + 1e-9, ys
                    bars += 1
    assert bars >= 2 * len(result["modalities"])  # the bars were found and checked


def test_sweep_axes_are_labelled_and_the_log_one_says_so(sweep_fig):
    fig, _ = sweep_fig
    for ax in fig.axes:
        assert ax.get_xlabel() and ax.get_ylabel()
        if ax.get_xscale() == "log":
            assert "log scale" in ax.get_xlabel(), ax.get_xlabel()
    assert sum(ax.get_xscale() == "log" for ax in fig.axes) == 2


def test_sweep_spells_f_perp_one_way(sweep_fig):
    fig, _ = sweep_fig
    texts = _texts(fig)
    assert any("F⊥+C" in t for t in texts), texts
    assert not any("Fperp" in t or "perp$" in t for t in texts), texts


def _trial_figs(run_dir: Path):
    run = open_run(str(run_dir))
    for p in run.participants:
        for t in p.trials:
            yield t, trial_figure(t, load_frames(t), run.criteria)


def _marked_points(line) -> set[tuple[float, float]]:
    """The (x, y) of the samples a line draws a marker at (its markevery)."""
    x, y = line.get_xdata(), line.get_ydata()
    start, step = line.get_markevery()
    return {(float(x[i]), float(y[i])) for i in range(start, len(x), step)}


def test_trial_pwm_lines_never_hide_each_other():
    checked = 0
    for trial, fig in _trial_figs(DATA / "study"):
        try:
            pwm_ax = fig.axes[1]
            lines = [ln for ln in pwm_ax.get_lines() if not ln.get_label().startswith("_")]
            assert len(lines) == trial.k
            looks = {(ln.get_marker(), str(ln.get_linestyle())) for ln in lines}
            assert len(looks) == trial.k, looks
            for a, b in itertools.combinations(lines, 2):
                # where two fingers' values are equal the lines lie on each other: their
                # markers sit on different samples, so both show
                assert not (_marked_points(a) & _marked_points(b)), (a.get_label(), b.get_label())
            checked += 1
        finally:
            pyplot().close(fig)
    assert checked >= 4


def test_trial_and_overview_titles_spell_f_perp_and_say_simulated(tmp_path):
    run = tmp_path / "study"
    shutil.copytree(DATA / "study", run)
    trials = run / "U1" / "trials.jsonl"
    rows = [json.loads(line) for line in trials.read_text().splitlines()]
    rows[0].update(modality="Fperp+V", policy="Fperp", simulated=True)
    trials.write_text("".join(json.dumps(r) + "\n" for r in rows))
    study = open_run(str(run))
    first = study.participants[0].trials[0]
    fig = trial_figure(first, load_frames(first), study.criteria)
    try:
        title = fig.axes[0].get_title(loc="left")
        assert "F⊥+V" in title and "policy F⊥" in title and "Fperp" not in title, title
        assert "SIMULATED participant" in title, title
    finally:
        pyplot().close(fig)
    fig = overview_figure(study.participants[0], study.criteria)
    try:
        texts = _texts(fig)
        assert any("SIMULATED participant" in t for t in texts), texts
        assert any("F⊥+" in t for t in texts) and not any("Fperp" in t for t in texts), texts
    finally:
        pyplot().close(fig)


@pytest.mark.parametrize("simulated", [True, False])
def test_a_stream_log_plot_says_simulated_when_the_log_does(tmp_path, simulated):
    session = tmp_path / "session"
    shutil.copytree(DATA / "session", session)
    config = json.loads((session / "config.json").read_text())
    config["simulated"] = simulated  # what `graspguide stream --log` records
    (session / "config.json").write_text(json.dumps(config))
    (trial, fig), *_ = list(_trial_figs(session))
    try:
        title = fig.axes[0].get_title(loc="left")
        assert ("SIMULATED" in title) is simulated, title
    finally:
        pyplot().close(fig)


def test_figure4_spells_f_perp_one_way(tmp_path):
    from analysis.test_analysis import make_study

    from graspguide.analysis import paper_tables as analysis

    make_study(tmp_path / "S", n=3)
    res = analysis.analyze([tmp_path / "S"])
    saved = []
    original = Figure.savefig

    def keep(self, *args, **kwargs):
        saved.append(self)
        return original(self, *args, **kwargs)

    Figure.savefig = keep
    try:
        analysis.write_outputs(res, tmp_path / "out")
    finally:
        Figure.savefig = original
    ticks = [t.get_text() for t in saved[0].axes[0].get_xticklabels()]
    assert ticks == ["F+C", "F⊥+C", "F+V", "F⊥+V"], ticks
