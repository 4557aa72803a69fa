"""Model figures: each returns a Figure with labelled axes (units) and saves atomically."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from matplotlib.figure import Figure

from bayes_amb.plots import (
    FigureError,
    plot_campbell,
    plot_rotor_sketch,
    plot_singular_values,
    save_figure,
)
from bayes_amb.reduction import reduce_pseudo_modal
from bayes_amb.reduction.fidelity import singular_value_data
from bayes_amb.rig import load_rig
from bayes_amb.rotor import campbell_data


@pytest.fixture(scope="module")
def rig():
    return load_rig()


@pytest.fixture(scope="module")
def sv(rig):
    return singular_value_data(reduce_pseudo_modal(rig), np.logspace(0, 4.7, 120))


@pytest.fixture(scope="module")
def cd(rig):
    return campbell_data(rig, np.linspace(0.0, 36000.0, 5), n_modes=4)


def test_singular_values_figure(sv):
    """Fig. 5 analogue: log frequency axis in rad/s, dB of m/A, marker at half the first
    bending frequency, 2 x 4 thin + 2 thick lines (full and reduced)."""
    fig = plot_singular_values(sv)
    assert isinstance(fig, Figure)
    ax = fig.axes[0]
    assert "rad/s" in ax.get_xlabel() and "dB" in ax.get_ylabel() and "m/A" in ax.get_ylabel()
    assert ax.get_xscale() == "log"
    xs = [line.get_xdata()[0] for line in ax.get_lines() if len(line.get_xdata()) == 2]
    assert any(x == pytest.approx(0.5 * sv.first_bending_rad_s) for x in xs)
    thick = [line for line in ax.get_lines() if len(line.get_xdata()) == sv.omega.size]
    assert len(thick) == 10
    np.testing.assert_allclose(thick[-2].get_ydata(), 20 * np.log10(sv.sv_full[:, 0]))


def test_campbell_figure(cd):
    """Hz against rpm; one line per mode, the 1x line f = rpm/60 and the running speed."""
    fig = plot_campbell(cd)
    ax = fig.axes[0]
    assert "Hz" in ax.get_ylabel() and "rpm" in ax.get_xlabel()
    labels = [line.get_label() for line in ax.get_lines()]
    assert any("1x" in s for s in labels) and any("running speed" in s for s in labels)
    sync = next(line for line in ax.get_lines() if "1x" in line.get_label())
    np.testing.assert_allclose(sync.get_ydata(), cd.speeds_rpm / 60.0)
    modes = [line for line in ax.get_lines() if "whirl" in line.get_label()
             or line.get_label().startswith("_child")]
    assert len(modes) == cd.freqs_hz.shape[1]


def test_rotor_sketch_figure(rig):
    """Lengths in mm; bearings, sensors and discs labelled by name."""
    fig = plot_rotor_sketch(rig)
    ax = fig.axes[0]
    assert "mm" in ax.get_xlabel() and "mm" in ax.get_ylabel()
    texts = " ".join(t.get_text() for t in ax.texts)
    for word in ("AMB A", "AMB B", "sensor A", "sensor B", "D1", "D2"):
        assert word in texts
    x0, x1 = ax.get_xlim()
    assert x0 < 0 and x1 > rig.shaft.length * 1e3


def test_plot_on_given_axes(sv):
    """Drawing on a caller's axes returns that axes' figure."""
    fig = Figure()
    ax = fig.add_subplot()
    assert plot_singular_values(sv, ax=ax) is fig


@pytest.mark.parametrize("suffix", [".png", ".svg", ".pdf"])
def test_save_figure_formats(tmp_path: Path, rig, suffix):
    """Saved files start with the format's signature and no temporary file is left."""
    path = save_figure(plot_rotor_sketch(rig), tmp_path / f"rotor{suffix}")
    head = path.read_bytes()[:64]
    magic = {".png": b"\x89PNG", ".svg": b"<?xml", ".pdf": b"%PDF"}[suffix]
    assert head.startswith(magic)
    assert [p.name for p in tmp_path.iterdir()] == [f"rotor{suffix}"]


def test_save_figure_replaces_existing_file(tmp_path: Path, rig):
    path = tmp_path / "fig.png"
    path.write_bytes(b"old")
    save_figure(plot_rotor_sketch(rig), path)
    assert path.read_bytes().startswith(b"\x89PNG")


def test_save_figure_rejects_unknown_extension(tmp_path: Path, rig):
    with pytest.raises(FigureError, match=r"unsupported extension '\.jpg'"):
        save_figure(plot_rotor_sketch(rig), tmp_path / "fig.jpg")
    assert list(tmp_path.iterdir()) == []
