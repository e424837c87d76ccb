"""The controller's timing values on /diagnostics (dualarm_control.ros.inputs.CycleTiming): the latency and the
last interval every cycle, the percentiles over the window only when refreshed (once a second of cycles)."""

from __future__ import annotations

import numpy as np

from dualarm_control.ros.inputs import CycleTiming

PERIOD = 0.001


def test_percentiles_change_only_when_refreshed_and_equal_numpys() -> None:
    timing = CycleTiming(realtime=False)
    first = timing.values(0.0, refresh=False)
    assert first["state_to_command_latency_p50_s"] == "nan"
    latencies = []
    for k in range(1, 301):
        latencies.append(timing.command(0, 0, PERIOD))
        values = timing.values(latencies[-1], refresh=False)
        assert values["state_to_command_latency_s"] == f"{latencies[-1]:.6e}"
        assert values["state_to_command_latency_p50_s"] == "nan", k  # not refreshed: the old percentiles
    refreshed = timing.values(latencies[-1], refresh=True)
    p50, p99 = np.percentile(np.array(latencies), [50.0, 99.0])
    assert refreshed["state_to_command_latency_p50_s"] == f"{p50:.6e}"
    assert refreshed["state_to_command_latency_p99_s"] == f"{p99:.6e}"
    assert set(refreshed) == {"period_jitter_p50_s", "period_jitter_p99_s", "state_interval_s",
                              "state_to_command_latency_s", "state_to_command_latency_p50_s",
                              "state_to_command_latency_p99_s"}

