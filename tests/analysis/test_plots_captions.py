"""The figures name their design: the caption of the configuration, the PNG's metadata, band marks, sweep markers.

docs/analyses.md, "What every analysis verb does". In-process: the verbs run tiny grids (one sweep direction: no
worker process).
"""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.text import Text
from PIL import Image

from rimd_sim import cli
from rimd_sim.analysis import plots
from rimd_sim.analysis.captions import DEFAULTS, describe, describe_parameters
from rimd_sim.analysis.dynamics.bifurcation import BifurcationBranch, BifurcationPoint
from rimd_sim.analysis.dynamics.sweep import SweepPoint, SweepResult, band_peak
from rimd_sim.analysis.plots import recorded
from rimd_sim.errors import ConfigError
from rimd_sim.settings.config import RigParams, SimConfig, load_config
from rimd_sim.settings.params import parameters

#: The new design of docs/analyses.md, "What every analysis verb does": four parameters away from the defaults.
DESIGN = {"mass": 1.0, "natural_frequency": 10.5, "damping_ratio": 0.02, "gap": 0.25e-3}
DESIGN_WORDS = ("mass 1 kg", "natural_frequency 10.5 Hz", "damping_ratio 0.02", "gap 0.25 mm")
YAML = """/**/rimd_simulator:
  ros__parameters:
    mass: 1.0
    natural_frequency: 10.5
    damping_ratio: 0.02
    gap: 0.25e-3
    motor:
      max_frequency: 30.0
"""


def _items(caption: str) -> list[str]:
    """The parameters a caption lists (after the models)."""
    return caption.split("; ", 1)[1].split(", ")


def test_default_config_has_default_parameters():
    caption = describe(load_config())
    assert caption == f"rigid model, spring_dashpot contact; {DEFAULTS}"
    assert describe(SimConfig()) == caption


def test_design_caption_names_exactly_its_four_parameters():
    caption = describe(SimConfig.from_parameters({**DESIGN, "motor.max_frequency": 30.0, "seed": 7,
                                                  "integrator.rtol": 1e-8}))
    assert caption.startswith("rigid model, spring_dashpot contact; ")
    assert sorted(_items(caption)) == sorted(DESIGN_WORDS)   # not the motor, the seed or the integrator
    assert "default" not in caption


def test_caption_covers_every_declared_mechanical_parameter():
    """Each parameter of RigParams (groups included) appears once changed, whatever it is: the declarations are
    iterated, so one added later needs no edit of the captions."""
    base = SimConfig()
    for name, p in parameters(RigParams).items():
        if p.kind != "float" or name in ("gap",):
            continue
        value = p.default * 1.5 if p.default else (p.low or 0) * 2 or 1.0
        try:
            config = base.with_parameters({name: value})
        except ConfigError:   # a rule between fields (impactor mass < mass, a pendulum >= g / w_n^2): another value
            other = p.default * 0.5 if p.default else (p.low + p.high) / 2
            config = base.with_parameters({name: other})
        assert [i.split(" ")[0] for i in _items(describe(config))] == [name], name
    assert _items(describe(base.with_parameters({"structure.model": "two_mass"}))) == [DEFAULTS]
    assert describe(base.with_parameters({"contact.model": "hertz"})).startswith("rigid model, hertz contact;")


def test_caption_omits_the_varied_parameter_and_reads_recorded_strings():
    config = SimConfig.from_parameters(DESIGN)
    assert "gap" not in describe(config, omit=("gap",))
    recorded = {k: repr(v) for k, v in DESIGN.items()} | {"contact.model": "spring_dashpot", "seed": "3"}
    assert describe_parameters(recorded) == describe(config)


def _design(tmp_path):
    path = tmp_path / "design.yaml"
    path.write_text(YAML)
    return path


def _metadata(png) -> dict[str, str]:
    with Image.open(png) as image:
        return dict(image.text)


def test_sweep_png_names_the_design_in_its_metadata(tmp_path):
    out = tmp_path / "sw"
    status = cli.main(["sweep", "--config", str(_design(tmp_path)), "--gap-mm", "0.25", "--f-min", "16",
                       "--f-max", "16.5", "--f-step", "0.5", "--direction", "up", "--cycles", "20",
                       "--measure-cycles", "8", "--accept-invalid", "--out", str(out)])
    assert status == 0
    meta = _metadata(out / "sweep.png")
    assert "gap 0.25 mm, sweep up" in meta["Title"]
    assert sorted(_items(meta["Description"])) == sorted(DESIGN_WORDS)


def test_bifurcation_png_names_the_design_in_its_metadata(tmp_path):
    out = tmp_path / "bif"
    status = cli.main(["bifurcation", "--config", str(_design(tmp_path)), "--gap-mm", "0.25", "--f-min", "16",
                       "--f-max", "16.2", "--f-step", "0.2", "--direction", "up", "--transient-cycles", "5",
                       "--sample-cycles", "4", "--accept-invalid", "--out", str(out)])
    assert status == 0
    meta = _metadata(out / "bifurcation.png")
    assert "stroboscopic displacement, sweep up" in meta["Title"]
    assert sorted(_items(meta["Description"])) == sorted(DESIGN_WORDS)


def _point(f: float, force: float, per_cycle: float) -> SweepPoint:
    label = {1.0: "1/1", 0.5: "1/2"}.get(per_cycle, "chaotic/non-periodic")
    return SweepPoint(frequency_hz=f, frequency_ratio=f / 10.5, peak_force_n=force, force_ratio=force / 9.81,
                      impacts_per_cycle=per_cycle, simulated_seconds=1.0, motion_class=label)


def _sweep(points) -> SweepResult:
    pts = tuple(points)
    return SweepResult(gap_mm=0.25, direction="rest", points=pts, band_a=band_peak(pts, 1.0),
                       band_b=band_peak(pts, 0.5), simulated_seconds=1.0, wall_seconds=1.0, workers=1)


def _texts(fig) -> list[Text]:
    return [t for t in fig.findobj(Text) if t.get_text()]


def test_sweep_without_band_b_writes_no_band_b_and_keeps_band_a_inside():
    result = _sweep(_point(f, 10 * (1 + (f == 18.0)), 1.0) for f in (16.0, 17.0, 18.0, 19.0, 20.0))
    assert result.band_a is not None and result.band_b is None
    fig, ax, _ = plots.sweep_figure([result])
    try:
        words = " ".join(t.get_text() for t in _texts(fig))
        assert "band A (1 impact per cycle): 18 Hz, 20 N" in words
        assert "band B" not in words and "none" not in words
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        frame = ax.get_window_extent(renderer)
        letters = [t for t in ax.texts if t.get_text() == "A"]
        assert len(letters) == 1
        box = letters[0].get_window_extent(renderer)
        # Inside the frame, not touching it (a label above the peak would run into the top edge).
        assert frame.x0 < box.x0 and box.x1 < frame.x1 and frame.y0 < box.y0 and box.y1 < frame.y1
        # The motor frequency in Hz on top of Omega/omega_n (f_n = 10.5 Hz).
        (top,) = ax.child_axes
        assert top.get_xlabel() == "motor frequency (Hz)"
        assert np.array(top.get_xlim()) == pytest.approx(np.array(ax.get_xlim()) * 10.5)
    finally:
        plots.plt.close(fig)


def test_sweep_without_any_band_writes_no_band():
    fig, _, _ = plots.sweep_figure([_sweep(_point(f, 5.0, 0.0) for f in (16.0, 17.0))])
    try:
        assert not any("band" in t.get_text() for t in _texts(fig))
    finally:
        plots.plt.close(fig)


def test_bifurcation_up_filled_down_hollow_coloured_by_class():
    def branch(direction):
        return BifurcationBranch(direction, (
            BifurcationPoint(16.0, 16 / 10.5, np.array([0.5, 0.5]), "1/1", 1.0),
            BifurcationPoint(17.0, 17 / 10.5, np.array([0.2, 0.8]), "1/2", 0.5)), 1.0)

    fig, ax = plots.bifurcation_figure([branch("up"), branch("down")])
    try:
        up, down = ax.collections[:2]
        colours = plots.class_palette(["1/1", "1/1", "1/2", "1/2"])
        from matplotlib.colors import to_rgba

        assert [tuple(c) for c in up.get_facecolors()] == [to_rgba(colours[c]) for c in ("1/1", "1/1", "1/2", "1/2")]
        assert len(down.get_facecolors()) == 0   # rings: hollow
        assert [tuple(c) for c in down.get_edgecolors()] == [tuple(c) for c in up.get_facecolors()]
        assert down.get_sizes()[0] > up.get_sizes()[0] >= 10   # both show where they coincide
        assert up.get_zorder() > down.get_zorder()
        legend = [t.get_text() for t in ax.get_legend().get_texts()]
        assert {"1/1", "1/2", "sweep up (filled dots)", "sweep down (rings)"} <= set(legend)
    finally:
        plots.plt.close(fig)


def test_the_impacts_figure_labels_its_steps_inside_the_axes_whatever_the_forces(tmp_path):
    """Each steady step is labelled with its setpoint at the foot of the axes: with every peak near 79 N the label
    once sat at 0 N, outside the figure, and matplotlib warned that the layout could not be made."""
    import warnings

    import matplotlib

    from rimd_sim.analysis.recordings.recorded import Step

    matplotlib.use("Agg")
    t = np.linspace(0.2, 9.8, 40)
    peaks = np.where(t < 5.0, 79.2, 76.7)
    steps = [Step(0, 3.75, 0.0, 0.5, 1.5, 5.0), Step(1, 4.0, 5.0, 5.6, 6.5, 10.0)]
    drawn = {}
    real_save = recorded._save

    def keep(fig, path, *args, **kwargs):
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        drawn["labels"] = [(t.get_text(), t.get_window_extent(renderer)) for t in fig.axes[0].texts]
        drawn["axes"] = fig.axes[0].get_window_extent(renderer).frozen()   # before the layout moves it
        return real_save(fig, path, *args, **kwargs)

    with warnings.catch_warnings():
        warnings.simplefilter("error")   # a layout that cannot be made is an error here
        recorded._save, saved = keep, recorded._save
        try:
            plots.plot_recorded_impacts(t, peaks, t, peaks + 0.05, steps, tmp_path / "impacts.png", "impacts")
        finally:
            recorded._save = saved
    assert [text for text, _ in drawn["labels"]] == ["3.75 Hz", "4 Hz"]
    box = drawn["axes"]
    for text, extent in drawn["labels"]:
        assert box.y0 <= extent.y0 and extent.y1 <= box.y1 and box.x0 <= extent.x0 <= box.x1, (text, extent, box)
    assert (tmp_path / "impacts.png").stat().st_size > 0
