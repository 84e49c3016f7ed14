"""``cdprctl send``'s ``KEY=VALUE`` fields as the payload the gateway reads (the documented
moves go through the same reading: tests/test_docs_commands.py)."""

from __future__ import annotations

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


def test_a_field_without_a_value_is_refused_before_any_session(capsys):
    """Nothing listens at port 1: the refusal comes from the field, at once (exit 2)."""
    with pytest.raises(ValueError, match="'position' is not KEY=VALUE"):
        fields_payload(["position"])
    assert main(["send", "--robot", "rowc", "--connect", "tcp/127.0.0.1:1", "move",
                 "position"]) == 2  # fmt: skip
    assert capsys.readouterr().err == "cdprctl send: error: 'position' is not KEY=VALUE\n"
