"""A computation in a process of its own (``cdprctl.core.child_compute``): its result, its
exception raised in the caller with its type, and a child that died said in one line."""

from __future__ import annotations

import functools
import math
import os

import numpy as np
import pytest

from cdprctl.core.child_compute import ChildComputationError, compute_in_child


def test_the_result_comes_back_from_another_process():
    pid = compute_in_child(os.getpid)
    assert pid != os.getpid()
    # an array of the size of a calibration's samples and back, bit for bit
    x = np.random.default_rng(7).normal(size=(400, 8))
    assert np.array_equal(compute_in_child(functools.partial(np.copy, x)), x)


def test_its_exception_is_raised_here_with_its_type():
    with pytest.raises(ValueError, match="math domain error"):
        compute_in_child(functools.partial(math.sqrt, -1.0))


def test_a_child_that_dies_is_one_clear_error():
    """Killed (here: it ends itself by ``os._exit`` before writing): no result, the exit."""
    said = "the computation's process ended with exit 3 and no result"
    with pytest.raises(ChildComputationError, match=said):
        compute_in_child(functools.partial(os._exit, 3))


def test_a_task_that_cannot_be_sent_is_refused_before_any_process():
    with pytest.raises((AttributeError, TypeError, __import__("pickle").PicklingError)):
        compute_in_child(lambda: 1)
