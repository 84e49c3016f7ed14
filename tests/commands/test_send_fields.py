"""``cdprctl send``'s ``KEY=VALUE`` fields as the payload the gateway reads (the documented
moves go through the same reading: tests/test_docs_commands.py)."""

from __future__ import annotations

import numpy as np
import pytest

from cdprctl.cli import main
from cdprctl.commands.zenoh_tools import fields_payload


def test_fields_become_numbers_vectors_booleans_and_words():
    fields = ["position=1.8,0.35,0.5", "max_velocity=0.1", "release=true", "method=sotda",
              "cable=3"]  # fmt: skip
    assert fields_payload(fields) == {
        "position": [1.8, 0.35, 0.5],
        "max_velocity": 0.1,
        "release": True,
        "method": "sotda",
        "cable": 3,
    }


def test_rpy_takes_degrees_where_a_value_ends_in_deg_and_refuses_a_bare_one_beyond_pi(capsys):
    """What ``workspace --rpy`` takes (``core.angles``): sent in radians; a bare 30 refused
    at once, before any session, with what it likely meant."""
    got = fields_payload(["rpy=0,-5deg,30°"])["rpy"]
    assert got == pytest.approx(np.deg2rad([0.0, -5.0, 30.0]), abs=1e-15)
    assert main(["send", "--robot", "rowc", "--connect", "tcp/127.0.0.1:1", "move",
                 "position=1.5,0.35,0.59", "rpy=0,0,30"]) == 2  # fmt: skip
    assert capsys.readouterr().err == (
        "cdprctl send: error: rpy: yaw = 30 is taken in radians and is beyond pi; did you mean "
        "degrees? 30° = 0.5236 rad: write it 30deg or 0.5236\n")
    with pytest.raises(ValueError, match=r"rpy: must be 3 finite numbers \(rad, or each"):
        fields_payload(["rpy=0,0"])
    with pytest.raises(ValueError, match=r"rpy: must be 3 finite numbers"):
        fields_payload(["rpy=0,0,0.1rad"])


def test_a_field_without_a_value_is_refused_before_any_session(capsys):
    """Nothing listens at port 1: the refusal comes from the field, at once (exit 2)."""
    with pytest.raises(ValueError, match="'position' is not KEY=VALUE"):
        fields_payload(["position"])
    assert main(["send", "--robot", "rowc", "--connect", "tcp/127.0.0.1:1", "move",
                 "position"]) == 2  # fmt: skip
    assert capsys.readouterr().err == "cdprctl send: error: 'position' is not KEY=VALUE\n"
