"""Fixtures shared by the command-line tests."""

import re

import pytest

from jaxgrav.cli import bench, main

OFFSET = "warning: the readings sit "
FLAT = "warning: the map along the track cannot tell the position"


def _check_filter_warnings(lines, offset, flat):
    """``filter_checks``' warnings among stderr ``lines``: one offset line matching the
    regular expression ``offset`` (None: no such line) and ``flat`` flat-map lines (0 or 1)."""
    offsets = [line for line in lines if line.startswith(OFFSET)]
    if offset is None:
        assert offsets == [], lines
    else:
        assert len(offsets) == 1, lines
        assert re.match(OFFSET + offset + r"(\.\d+)? mGal from the map along the INS track",
                        offsets[0]), offsets
        assert "subtract the offset from the gravity column" in offsets[0]
    flats = [line for line in lines if line.startswith(FLAT)]
    assert len(flats) == int(flat), lines
    if flat:
        assert "more than the filter's own 1-sigma" in flats[0], flats


@pytest.fixture
def check_filter_warnings():
    """The check of ``filter`` and ``navigate``'s offset and flat-map warnings, as a
    callable ``(stderr lines, offset regex or None, flat: bool)``."""
    return _check_filter_warnings


@pytest.fixture
def quick_machine_info(monkeypatch):
    """``jaxgrav bench``'s machine description without measuring the roofline (3 s saved)."""
    monkeypatch.setattr(bench, "machine_info", lambda: {
        "cpu": "c", "arch": "a", "cores": 1, "load_average": [0, 0, 0], "jax": "j",
        "jaxgrav": "g", "devices": ["d"], "roofline": {"n": 1, "float64_gflops": 1.0,
                                                       "float32_gflops": 1.0}})


@pytest.fixture
def refused(capsys):
    """``refused(argv, message)``: the command ``argv`` exits 2 with one stderr line (no
    traceback) holding ``message``; returns that line."""
    def check(argv, message):
        assert main([str(a) for a in argv]) == 2
        err = capsys.readouterr().err.strip()
        assert message in err, err
        assert "\n" not in err and "Traceback" not in err, err
        return err

    return check
