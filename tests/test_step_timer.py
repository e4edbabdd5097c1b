"""avp_monitor.step_timer: the closed-loop step time of one ego from observation and command timestamps (ns)."""

from __future__ import annotations

import numpy as np

from avp_monitor.step_timer import StepTimer, summary_ms

MS = 1_000_000
STEP = 100 * MS  # stamps of dt = 0.1 s


def test_step_times_resends_copies_late_answers_and_a_new_episode():
    t = StepTimer()
    assert t.on_obs(0, 1_000 * MS)
    assert not t.on_obs(0, 1_000 * MS + 1)  # a duplicate delivery, not a re-send
    assert t.on_obs(0, 2_500 * MS)  # a lock-step re-send 1.5 s later (RESEND_ANSWER_INTERVAL 1 s)
    t.on_cmd(0, 2_520 * MS)  # answers the re-send: 20 ms
    t.on_cmd(0, 2_900 * MS)  # a second command for step 0 does not count
    assert t.on_obs(STEP, 2_600 * MS)
    assert t.on_obs(2 * STEP, 2_700 * MS)
    assert not t.on_obs(STEP, 2_710 * MS)  # an older step's stale copy (step 0 again would be a new episode)
    t.on_cmd(STEP, 2_750 * MS)  # after observation 2 was sent: late
    lat, late = t.step_times()
    assert np.allclose(lat, [0.020, 0.150]) and late == 1
    assert not t.restarts(STEP) and t.restarts(0)
    assert t.on_obs(0, 5_000 * MS)  # time back at 0: a new episode, the old steps are gone
    assert t.obs_sent == {0: [5_000 * MS]} and t.cmd_received == {} and t.step_times()[0].size == 0


def test_summary_ms():
    assert summary_ms(np.array([])) == {}
    s = summary_ms(np.array([0.010, 0.020, 0.030]))
    assert s["median_ms"] == 20.0 and s["max_ms"] == 30.0 and s["min_ms"] == 10.0 and s["mean_ms"] == 20.0
