"""The reliability matrix (cdprctl/experiments/scenarios.py) in lock-step, one test per fault: the
invariants hold in every run (no non-finite torque, no torque beyond its limit, no commanded
tension outside [t_min, t_max] while healthy, no cable contact in the simulated robot), every
fault ends in a documented state, and the recoverable ones recover. docs/reliability.md is the
table of these same runs (tools/reliability_table.py)."""

from __future__ import annotations

import pytest

from cdprctl.experiments.scenarios import SCENARIOS, run

RIDE_THROUGH = {"frame loss 1 %", "frames delayed 3 ms"}
STOPS = {
    "drive fault (0x2310)",
    "drive silent 1 s",
    "encoder jump 0.5 rad",
    "cable snaps",
    "winch slips 0.05 m/s",
    "400 N lateral force",
}
ESTOPS = {"e-stop mid-move, released after 1 s", "e-stop released at once (20 ms)",
          "e-stop under the 30 N water jet"}  # fmt: skip
# brakes that take 30 ms to close: the drums free meanwhile (docs/safety.md)
SLOW_BRAKES = {"e-stop, brakes closing in 30 ms",
               "e-stop released while the brakes close (10 of 30 ms)"}  # fmt: skip
RECOVERS = {  # or rode through
    *ESTOPS,
    "frame loss 5 %",
    "frame loss 20 %",
    "frames corrupted 5 %",
    "drive fault (0x2310)",
    "drive silent 1 s",
}


@pytest.mark.parametrize("scenario", SCENARIOS, ids=[s.name for s in SCENARIOS])
def test_fault(rowc, scenario):
    r = run(rowc, scenario, seed=1)
    assert r.invariants_hold, vars(r)
    # the simulated robot's cables at its true pose, every step: no contact, whatever the fault
    # (the closest, a snapped cable's, 14.4 mm; measured, not the initial infinity)
    assert r.contacts == 0 and 0.0 < r.least_clearance_mm < 1e3, vars(r)
    name = scenario.name
    if name in RIDE_THROUGH:
        assert r.detection_s is None, r.reaction
        assert r.recovered.startswith("rode through"), r.recovered
        assert r.excursion_mm < 5.0
    if name in STOPS:
        assert r.detection_s is not None and r.detection_s < 0.5, r.reaction
        assert r.reaction.startswith(("fault", "stopping")), r.reaction
    if name in RECOVERS:
        assert r.recovered.startswith(("yes", "rode through")), r.recovered
    if name == "drive fault (0x2310)":
        assert r.detection_s < 0.01 and "0x2310" in r.reaction
    if name == "encoder jump 0.5 rad":  # the drive's own following error stops it at once
        assert "0x8611" in r.reaction and r.excursion_mm < 1.0, (r.reaction, r.excursion_mm)
    if name == "winch slips 0.05 m/s":  # the stop reels the slipping cable in to its tension
        assert r.excursion_mm < 10.3, r.excursion_mm  # torque mode's; 25.4 held, 8.5 reeled in
    if name == "cable snaps":
        # 40.1 measured on rowc's offset geometry (issue 67), 34.0 on the layout before (torque
        # mode 163): the remaining cables take the load as the new layout shares it
        assert r.excursion_mm < 45.0, r.excursion_mm
    if name in ESTOPS | SLOW_BRAKES:  # its own state, never a fault
        assert r.detection_s is not None and r.detection_s < 0.01, r.reaction
        assert r.reaction.startswith("estop: emergency stop") and r.fault_kind == "", r.reaction
    if name in ESTOPS:  # the drop onto brakes that close at once is small
        # 1.7 mm measured; under the jet 8.0 (the jet goes on pushing the braked platform)
        assert r.excursion_mm < (10.0 if "jet" in name else 3.0), r.excursion_mm
    if name in SLOW_BRAKES:
        # 30 ms of free drums: the tensions fall to zero within 16 ms, the drums pay out
        # slack and the platform drops 28 mm (lock-step); re-enabled on slack cables the
        # encoders fit no pose: refused, as it must be (docs/safety.md, "Stop categories")
        assert 20.0 < r.excursion_mm < 40.0, r.excursion_mm
        assert r.recovered.startswith("no: fault the encoders disagree"), r.recovered
    if name == "daemon SIGKILLed, restarted":
        assert r.detection_s is not None and r.detection_s <= 0.15  # the drives' timeout
        assert r.recovered.startswith("yes"), r.recovered


def test_five_percent_frame_loss_no_target_taken_late(rowc):
    """5 % frame loss, seed 7: SYNCs lost, then RPDOs, left targets waiting that were for the
    lost SYNCs; taken a period late they put drives a period behind (1.5 mm of excursion).
    With the SYNC's counter (0x1019) the drives do not take them (docs/drivers.md)."""
    sc = next(s for s in SCENARIOS if s.name == "frame loss 5 %")
    r = run(rowc, sc, seed=7)
    assert r.detection_s is None, r.reaction
    assert r.excursion_mm < 0.5
