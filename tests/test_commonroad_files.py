"""Every published CommonRoad file reads and drives, or is refused with one line naming the file,
the element and the reason (``tests/data/commonroad``; provenance in its README)."""

from pathlib import Path

import numpy as np
import pytest

from mpcdrive.adapters.commonroad import available

if not available():
    pytest.skip(
        "the commonroad extra (commonroad-io, commonroad-drivability-checker) is not installed", allow_module_level=True
    )

from mpcdrive.adapters.commonroad import load_commonroad  # noqa: E402

DIR = Path(__file__).resolve().parent / "data" / "commonroad"


def test_a_trajectory_repeating_its_initial_time_step_reads_once():
    """DEU_Cologne-63_5_I-1 (written by the interactive-scenario simulation) begins every
    recorded trajectory at the initial time step, repeating the initial state: that step is read
    once, and the obstacles move as recorded."""
    imp = load_commonroad(DIR / "DEU_Cologne-63_5_I-1.xml.gz")
    dynamic = {o.obstacle_id: o for o in imp.scenario.dynamic_obstacles}
    assert len(dynamic) == 34 and len(imp.spec.obstacles) == 34
    for o, entry in zip(imp.scenario.obstacles, imp.spec.obstacles):
        traj = entry.trajectory
        assert traj is not None, entry.name
        t = np.asarray(traj.t_s)
        assert t[0] == pytest.approx(o.initial_state.time_step * imp.spec.dt_s)
        assert np.all(np.diff(t) > 0), entry.name
        recorded = o.prediction.trajectory.state_list
        assert recorded[0].time_step == o.initial_state.time_step  # the repeat is in the file
        # one point per recorded step (the repeated one once) and the extrapolated end
        assert len(traj.points) == len(recorded) + 1
        assert traj.points[0] == pytest.approx(tuple(recorded[0].position))
        assert traj.points[-2] == pytest.approx(tuple(recorded[-1].position))
