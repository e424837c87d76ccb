"""`dualarm bench` end to end on a tiny random set (no timing asserts: speed goes into the bench)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from dualarm_control.app.bench.suite import run_bench, solver_configs
from dualarm_control.app.cli import main
from dualarm_control.controller import ControllerParams
from dualarm_control.solvers import make_solver


def test_bench_writes_every_part(tmp_path: Path) -> None:
    """bench.json has the random set (every accepted solver x back-end), refusals, exactness and scaling."""
    argv = ["bench", "--scenario", "none", "--cases", "6", "--solver", "standard_qp,sparse_qp",
            "--backend", "daqp,quadprog", "--collision-robots", "none", "--output", str(tmp_path)]
    assert main(argv) == 0
    record = json.loads((tmp_path / "bench.json").read_text())
    rows = record["random"]["rows"]
    assert {"standard_qp | daqp", "standard_qp | quadprog", "sparse_qp | daqp"} <= set(rows)
    assert "sparse_qp | quadprog" in record["refused"] and "semi-definite" in record["refused"]["sparse_qp | quadprog"]
    for name in ("standard_qp | daqp", "sparse_qp | daqp"):
        row = rows[name]
        assert row["failures"] == 0 and row["samples"] == 6
        assert 0 <= row["max_bound_excess"] <= make_solver(name.split(" | ")[0]).bound_tolerance
        assert 0 < row["cycle_p50_ms"] <= row["cycle_p99_ms"]
        assert 0 < row["cpu_p50_ms"] <= row["cpu_p99_ms"]  # the thread's CPU time: no preemption in it
        assert row[record["random"]["ratio_columns"][0]] > 0
    assert rows["sparse_qp | daqp"]["active_joints_max"] <= 6
    # the daqp QP solvers again with the collision limit on (issue 39's target), none for the other back-ends
    with_limit = {name for name in rows if name.endswith(", collision limit")}
    assert with_limit == {"standard_qp | daqp, collision limit", "sparse_qp | daqp, collision limit"}
    for name in with_limit:
        assert rows[name]["samples"] == 6 and rows[name]["failures"] == 0 and rows[name]["cycle_p50_ms"] > 0
    assert record["exactness"]["cases"] == 6
    assert {r["arms"] for r in record["scaling"].values()} == {2, 3, 4}
    text = (tmp_path / "bench.md").read_text()
    assert "| sparse_qp | daqp |" in text and "| sparse_qp | daqp, collision limit |" in text
    assert "Exactness" in text and "Scaling" in text


def test_pseudo_inverse_is_listed_once() -> None:
    """A solver without a QP does not depend on the back-end: one row, back-end '-'."""
    configs, refused = solver_configs(ControllerParams(), ["pseudo_inverse"], ["daqp", "proxsuite"])
    assert list(configs) == ["pseudo_inverse | -"] and not refused


def test_unknown_backend_exits_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "--scenario", "none", "--backend", "nope", "--output", str(tmp_path)]) == 2
    assert "nope" in capsys.readouterr().err


def test_run_bench_without_scenario_has_no_scenario_part() -> None:
    record = run_bench(None, ["standard_qp"], ["daqp"], count=4, scaling_arms=(2,))
    assert "scenario" not in record and record["random"]["cases"] == 4


def test_realtime_bench_refuses_a_missing_params_file(tmp_path: Path) -> None:
    """`dualarm bench --realtime --params F`: a missing file exits 2 before any node starts."""
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-m", "dualarm_control.app.cli", "bench", "--realtime", "--rates", "1000",
                          "--params", str(tmp_path / "missing.yaml"), "--output", str(tmp_path)],
                         check=False, capture_output=True, text=True, timeout=120)
    assert out.returncode == 2 and "file not found" in out.stderr
    assert not (tmp_path / "realtime.md").exists()


def test_the_1khz_realtime_params_file_sets_only_the_trajectory_nodes_scheduling() -> None:
    from dualarm_control.paths import config_path
    from dualarm_control.ros.priority import priority_from_args

    path = str(config_path("realtime_1khz.yaml"))
    args = ["x", "--ros-args", "--params-file", path]
    assert priority_from_args(args, 40, "trajectory_node") == 0
    assert priority_from_args(args, 50, "controller_node") == 50 and priority_from_args(args, 50, "sim_node") == 50


def test_message_bench_times_both_paths(tmp_path: Path) -> None:
    """`dualarm bench --messages`: every per-period message timed through rclpy objects and as CDR
    bytes in one run (no timing asserts), written as messages.md/json."""
    from dualarm_control.ros.message_bench import (
        format_message_bench,
        run_message_bench,
        write_message_bench,
    )

    rows = run_message_bench(number=20, repeat=1)
    assert [r["message"].split()[0] for r in rows] == ["/joint_states", "/relative_target", "/diagnostics",
                                                       "/velocity_controller/commands", "/joint_states"]
    assert all(r["rclpy_us"] > 0 and r["cdr_us"] > 0 and r["ratio"] == r["cdr_us"] / r["rclpy_us"] for r in rows)
    write_message_bench(tmp_path, rows)
    assert json.loads((tmp_path / "messages.json").read_text()) == rows
    assert format_message_bench(rows) in (tmp_path / "messages.md").read_text()


def test_realtime_and_messages_are_separate(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "--realtime", "--messages", "--output", str(tmp_path)]) == 2
    assert "choose one" in capsys.readouterr().err


def test_with_view_belongs_to_realtime(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "--with-view", "--output", str(tmp_path)]) == 2
    assert "--with-view belongs to --realtime" in capsys.readouterr().err


def test_realtime_table_has_a_view_column_only_with_view() -> None:
    """`dualarm bench --realtime --with-view` rows carry "view"; the table then says which run had it."""
    from dualarm_control.app.bench.realtime import format_realtime

    row = {"solver": "sparse_qp", "rate_hz": 500.0, "exit": 0, "cycles": 100, "missed_deadlines": 2,
           "missed_share": 0.02, "jitter_p50_ms": 0.1, "jitter_p99_ms": 1.0, "latency_p50_ms": 0.5,
           "latency_p99_ms": 2.0, "solver_failures": 0}
    plain = format_realtime([row])
    assert "view" not in plain and "| sparse_qp | 500 | 100 | 2 (2.00%) |" in plain
    table = format_realtime([{**row, "view": "none"}, {**row, "view": "rerun", "missed_deadlines": 5}])
    assert "| view |" in table.splitlines()[0]
    assert "| sparse_qp | 500 | none | 100 | 2 (2.00%) |" in table
    assert "| sparse_qp | 500 | rerun | 100 | 5 (2.00%) |" in table


# --- dualarm bench --realtime: CPU of the nodes (issue 21) -----------------------------------------

# /proc/PID/stat lines (proc(5)): pid (comm) state ppid ... utime (14) stime (15) ...; a comm may hold
# spaces and parentheses.
STAT_MAIN = ("4242 (python) S 4000 4242 4000 0 -1 4194560 24069 0 0 0 310 45 0 0 -11 0 17 0 123456 "
             "1164742656 31536 18446744073709551615 1 1 0 0 0 0 0 16781312 16386 0 0 0 17 1 50 1 0 0 0")
STAT_ODD = ("4250 (dds.ev (x) 1) R 4000 4242 4000 0 -1 4194624 12 0 0 0 7 3 0 0 -51 0 17 0 123460 "
            "1164742656 31536 18446744073709551615 1 1 0 0 0 0 0 16781312 16386 0 0 0 17 0 50 1 0 0 0")
STAT_ZOMBIE = "4251 (python) Z 4000 4242 4000 0 -1 4227084 0 0 0 0 1 1 0 0 20 0 1 0 123470 0 0 0"


def test_proc_stat_fields_are_read_after_the_command_name() -> None:
    from dualarm_control.app.bench.cpu import stat_ppid, stat_running, stat_ticks

    assert stat_ticks(STAT_MAIN) == 355 and stat_ppid(STAT_MAIN) == 4000 and stat_running(STAT_MAIN)
    assert stat_ticks(STAT_ODD) == 10 and stat_ppid(STAT_ODD) == 4000 and stat_running(STAT_ODD)
    assert not stat_running(STAT_ZOMBIE)


def test_a_child_is_named_by_the_module_it_runs_tools_left_out() -> None:
    from dualarm_control.app.bench.cpu import module_of, thread_kind

    py = "/venv/bin/python"
    assert module_of([py, "-u", "-m", "dualarm_control.nodes.controller_node", "--ros-args"]) == "controller_node"
    assert module_of([py, "-u", "-m", "dualarm_sim.sim_node"]) == "sim_node"
    assert module_of([py, "-u", "-m", "dualarm_control.nodes.container", "--nodes", "controller_node,trajectory_node",
                      "--ros-args"]) == "controller+trajectory"
    assert module_of([py, "-m", "some.other_module"]) == "some.other_module"
    assert module_of([py, "-u", "-m", "dualarm_control.app.cli", "bag", "record", "-o", "x"]) is None
    assert module_of([py, "-m", "dualarm_control.app.cli", "view", "--save", "v.rrd"]) is None
    assert module_of([py, "-S", "-c", "while True: pass"]) is None and module_of(["stress-ng", "--cpu", "1"]) is None
    assert thread_kind("dds.udp.7412") == "dds.udp" and thread_kind("dds.ev") == "dds.ev"


def test_scheduling_names() -> None:
    from dualarm_control.app.bench.cpu import scheduling_name

    assert scheduling_name(os.SCHED_FIFO, 50) == "fifo 50" and scheduling_name(os.SCHED_OTHER, 0) == "other"


def _proc(pid: int, total: int, **threads: int) -> object:
    from dualarm_control.app.bench.cpu import ProcessSample

    ticks = {int(k[1:]): v for k, v in threads.items()}
    return ProcessSample(pid, total, ticks, {tid: ("python" if tid == pid else f"dds.ev.{tid}") for tid in ticks})


def test_cpu_split_main_thread_and_the_others() -> None:
    """A thread started in the window counts from 0; one that exited counts to its last reading."""
    from dualarm_control.app.bench.cpu import CLOCK_TICKS, cpu_split

    samples = [_proc(10, 100, t10=80, t11=20),
               _proc(10, 160, t10=120, t11=30, t12=10),
               _proc(10, 240, t10=180, t12=30)]  # thread 11 exited after its 30 ticks
    split = cpu_split(samples)  # type: ignore[arg-type]
    assert split.total_s == 140 / CLOCK_TICKS and split.main_s == 100 / CLOCK_TICKS
    assert split.other_s == (10 + 30) / CLOCK_TICKS and split.threads == 3
    assert split.kinds == {"dds.ev": 40 / CLOCK_TICKS}
    assert split.main_s + split.other_s == split.total_s


def test_the_steady_window_starts_after_the_nodes_are_up_and_cycle_and_ends_before_one_exits() -> None:
    from dualarm_control.app.bench.cpu import Sample, steady_window

    a, b = _proc(1, 0, t1=0), _proc(2, 0, t2=0)
    samples = [Sample(0.0, {"sim_node": a}), Sample(1.0, {"sim_node": a, "controller_node": b}),
               *[Sample(t, {"sim_node": a, "controller_node": b}) for t in (2.0, 3.0, 4.0, 5.0, 6.0)],
               Sample(7.0, {"sim_node": a})]
    assert steady_window(samples, first_cycle=1.5, settle=2.0) == (4, 6)  # from 3.5 s: 4.0 s .. 6.0 s
    assert steady_window(samples, first_cycle=0.0, settle=2.0) == (3, 6)  # all up at 1.0 s
    assert steady_window(samples, first_cycle=4.5, settle=2.0) is None  # one sample left: no window
    assert steady_window([], first_cycle=0.0) is None


def test_cpu_figures_per_node_per_cycle_and_control_math() -> None:
    """200 cycles in a 2 s window; cycles and math are read from the controller's reports in it."""
    from dualarm_control.app.bench.cpu import CLOCK_TICKS, Sample, cpu_figures

    hz = CLOCK_TICKS
    samples = [Sample(t, {"controller_node": _proc(5, int(t * hz * 0.5), t5=int(t * hz * 0.4), t6=int(t * hz * 0.1)),
                          "sim_node": _proc(7, int(t * hz * 0.25), t7=int(t * hz * 0.25))})
               for t in (0.0, 1.0, 2.0, 3.0, 4.0)]
    stamps = np.arange(0.5, 4.5, 0.01)  # a report every 10 ms (100 Hz) from t = 0.5 s
    cycles = np.arange(1, len(stamps) + 1, dtype=float)
    cycle_time = np.full(len(stamps), 2e-4)
    fig = cpu_figures(samples, stamps, cycles, cycle_time, settle=1.0)
    assert fig["window_s"] == 2.0 and fig["window_cycles"] == 200  # 2.0 s .. 4.0 s
    ctrl, sim = fig["nodes"]["controller_node"], fig["nodes"]["sim_node"]
    assert list(fig["nodes"]) == ["controller_node", "sim_node"]
    assert ctrl["cores"] == pytest.approx(0.5) and ctrl["cpu_ms_per_cycle"] == pytest.approx(5.0)
    assert ctrl["main_ms_per_cycle"] == pytest.approx(4.0) and ctrl["other_ms_per_cycle"] == pytest.approx(1.0)
    assert sim["cores"] == pytest.approx(0.25) and sim["other_ms_per_cycle"] == 0.0
    assert fig["all_nodes_cores"] == pytest.approx(0.75) and fig["all_nodes_ms_per_cycle"] == pytest.approx(7.5)
    assert fig["control_math_ms_per_cycle"] == pytest.approx(0.2) and fig["control_math_reports"] == 200
    assert fig["control_math_s"] == pytest.approx(200 * 2e-4)
    assert cpu_figures(samples, stamps[:0], cycles[:0], cycle_time[:0]) == {}


def test_variants_interleave_the_baseline_before_the_current_tree() -> None:
    from dualarm_control.app.bench.realtime import variants

    runs = variants(["sparse_qp"], [200.0, 1000.0], ["none", "busy"], ["rt"], baseline=("bf34bc7", Path("/b")),
                    current="707482f")
    assert [(v.rate_hz, v.load, v.tree) for v in runs] == [
        (200.0, "none", "bf34bc7"), (200.0, "none", "707482f"), (200.0, "busy", "bf34bc7"), (200.0, "busy", "707482f"),
        (1000.0, "none", "bf34bc7"), (1000.0, "none", "707482f"), (1000.0, "busy", "bf34bc7"),
        (1000.0, "busy", "707482f")]
    assert runs[0].baseline == Path("/b") and runs[1].baseline is None
    assert [v.scheduling for v in variants(["a"], [1.0], schedulings=["rt", "normal"])] == ["rt", "normal"]
    layouts = variants(["a"], [1.0], baseline=("bf34bc7", Path("/b")), current="now", processes=[3, 1])
    assert [(v.tree, v.processes) for v in layouts] == [("bf34bc7", 3), ("now", 3), ("now", 1)]


def test_a_baseline_with_the_container_runs_in_each_layout_before_the_current_tree(tmp_path: Path) -> None:
    """An A/B of ``--processes 1`` compares the same layout when the baseline checkout has ``cell_container``."""
    from dualarm_control.app.bench.realtime import CONTAINER_MODULE, variants

    (tmp_path / CONTAINER_MODULE).parent.mkdir(parents=True)
    (tmp_path / CONTAINER_MODULE).write_text("")
    layouts = variants(["a"], [1.0], baseline=("cb29c1b", tmp_path), current="now", processes=[3, 1])
    assert [(v.tree, v.processes) for v in layouts] == [("cb29c1b", 3), ("now", 3), ("cb29c1b", 1), ("now", 1)]


@pytest.mark.parametrize("argv, named", [
    (["--load", "none,heavy"], "'heavy'"),
    (["--scheduling", "fifo"], "'fifo'"),
    (["--processes", "3,4"], "'4'"),
    (["--baseline", "/nonexistent/tree"], "/nonexistent/tree"),
])
def test_realtime_variants_refuse_unknown_values(argv: list[str], named: str, tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """An unknown --load/--scheduling value or a --baseline that is not a checkout exits 2 naming it."""
    assert main(["bench", "--realtime", *argv, "--output", str(tmp_path)]) == 2
    assert named in capsys.readouterr().err
    assert not (tmp_path / "realtime.md").exists()


def test_a_baseline_must_be_a_checkout_of_the_packages(tmp_path: Path) -> None:
    """A git repository without the packages is refused too, naming it."""
    import subprocess

    from dualarm_control.app.bench.realtime import baseline_tree
    from dualarm_control.errors import DualArmError

    subprocess.run(["git", "init", "-q", str(tmp_path)], check=True)
    with pytest.raises(DualArmError, match=str(tmp_path)):
        baseline_tree(tmp_path)


def test_load_and_scheduling_belong_to_realtime(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "--load", "busy", "--output", str(tmp_path)]) == 2
    assert "--load belongs to --realtime" in capsys.readouterr().err


def test_baseline_nodes_import_the_baseline_tree_whatever_the_current_directory(tmp_path: Path) -> None:
    """tree_environment: a node process started from this checkout's directory (``python -m`` puts
    the current directory first) imports the baseline's packages; baseline_tree labels it."""
    import subprocess
    import sys

    from dualarm_control.app.bench.realtime import baseline_tree, tree_environment

    base = tmp_path / "base"
    for pkg in ("dualarm_control", "dualarm_sim"):
        (base / pkg).mkdir(parents=True)
        (base / pkg / "__init__.py").write_text("")
    (base / "dualarm_control" / "probe.py").write_text("print(__file__)\n")
    git = ["git", "-C", str(base), "-c", "user.name=t", "-c", "user.email=t@t"]
    subprocess.run(["git", "init", "-q", str(base)], check=True)
    subprocess.run([*git, "add", "-A"], check=True)
    subprocess.run([*git, "commit", "-qm", "base"], check=True)
    head = subprocess.run([*git, "rev-parse", "--short", "HEAD"], check=True, capture_output=True,
                          text=True).stdout.strip()
    assert baseline_tree(base) == head
    here = Path(__file__).resolve().parents[1]
    out = subprocess.run([sys.executable, "-m", "dualarm_control.probe"], cwd=here, capture_output=True, text=True, check=False,
                         env={**os.environ, **tree_environment(base)}, timeout=60)
    assert out.stdout.strip() == str(base / "dualarm_control" / "probe.py"), out.stderr


def test_normal_scheduling_wins_over_a_users_node_priority(tmp_path: Path) -> None:
    """--scheduling normal: its file, after the user's, sets thread_priority 0 for every node, both as
    the node reads it before rclpy (priority_from_args) and as rclpy declares it."""
    import rclpy
    from rclpy.node import Node

    from dualarm_control.app.bench.realtime import NORMAL_SCHEDULING
    from dualarm_control.ros.priority import priority_from_args

    user = tmp_path / "user.yaml"
    user.write_text("/**:\n  ros__parameters:\n    thread_priority: 30\n"
                    "controller_node:\n  ros__parameters:\n    thread_priority: 60\n")
    normal = tmp_path / "normal.yaml"
    normal.write_text(NORMAL_SCHEDULING)
    args = ["x", "--ros-args", "--params-file", str(user), "--params-file", str(normal)]
    for name in ("controller_node", "sim_node", "trajectory_node", "any_node"):
        assert priority_from_args(args, 50, name) == 0
        assert priority_from_args(args[:4], 50, name) in (30, 60)  # without it: the user's
    context = rclpy.Context()
    rclpy.init(args=args, context=context)
    try:
        node = Node("controller_node", context=context, start_parameter_services=False)
        assert node.declare_parameter("thread_priority", 50).value == 0
        node.destroy_node()
    finally:
        context.try_shutdown()


def test_cpu_table_has_a_column_pair_per_node_and_all_nodes() -> None:
    from dualarm_control.app.bench.realtime import format_cpu

    node = {"cores": 0.25, "cpu_ms_per_cycle": 1.25, "main_ms_per_cycle": 1.0, "other_ms_per_cycle": 0.25}
    cpu = {"window_s": 20.0, "window_cycles": 4000, "nodes": {"sim_node": node, "controller_node": node},
           "control_math_ms_per_cycle": 0.2, "all_nodes_cores": 0.5, "all_nodes_ms_per_cycle": 2.5}
    rows = [{"solver": "sparse_qp", "rate_hz": 200.0, "load": "busy", "cpu": cpu},
            {"solver": "sparse_qp", "rate_hz": 200.0, "load": "none", "cpu": {}}]
    lines = format_cpu(rows).splitlines()
    assert lines[0].startswith("| solver | rate [Hz] | load | window [s] | cycles | control math / cycle [ms, wall] | "
                               "controller [core] | ")
    assert "| sim [core] |" in lines[0] and lines[0].endswith("[ms] |")
    assert all(line.count("|") == lines[0].count("|") for line in lines)
    assert lines[2] == ("| sparse_qp | 200 | busy | 20.0 | 4000 | 0.200 | 0.250 | 1.250 = 1.000 + 0.250 | 0.250 | "
                        "1.250 = 1.000 + 0.250 | 0.500 | 2.500 |")
    assert "no steady window" in lines[3]


def fifo_permitted() -> bool:
    """Whether a process may take SCHED_FIFO here (root or an rtprio limit; not on a CI runner)."""
    import subprocess
    import sys

    probe = "import os; os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))"
    return subprocess.run([sys.executable, "-S", "-c", probe], check=False, capture_output=True).returncode == 0


@pytest.mark.slow
def test_realtime_bench_measures_every_nodes_cpu(tmp_path: Path) -> None:
    """Two real launches at 200 Hz, each cut after 15 s, with the default and with normal scheduling:
    CPU figures for the three node processes, finite and positive, main + other threads = the
    process's total within the tick truncation of each thread's counter, the scheduling each node
    ran under; the tables and the JSON are written (no timing thresholds). ``slow`` (33 s): the
    default run covers the parts on recorded or simulated samples (the tests above and below: the
    steady window, the per-thread split, the per-node figures, the scheduling names, the floor probe
    in its own process)."""
    from dualarm_control.app.bench.cpu import CLOCK_TICKS
    from dualarm_control.app.bench.realtime import (
        format_cpu,
        run_realtime,
        write_realtime,
    )

    rows = run_realtime("assembly", ["hierarchical_sparse_qp"], [200.0], timeout=15.0, schedulings=["rt", "normal"])
    fifo = fifo_permitted()
    for row in rows:
        cpu = row["cpu"]
        assert cpu, {k: row.get(k) for k in ("exit", "cycles", "cpu_samples", "first_cycle_s")}  # a steady window
        assert set(cpu["nodes"]) == {"controller_node", "sim_node", "trajectory_node"}
        assert cpu["window_s"] > 0 and cpu["window_cycles"] > 0
        for name, node in cpu["nodes"].items():
            for key in ("cores", "cpu_ms_per_cycle", "main_ms_per_cycle", "other_ms_per_cycle"):
                assert np.isfinite(node[key]) and node[key] > 0, (name, key, node)
            assert abs(node["main_s"] + node["other_s"] - node["cpu_s"]) <= node["threads"] / CLOCK_TICKS, node
            default = "fifo 40" if name == "trajectory_node" else "fifo 50"
            assert node["scheduling"] == (default if fifo and row["scheduling"] == "rt" else "other"), (row, name)
        assert np.isfinite(cpu["control_math_ms_per_cycle"]) and cpu["control_math_ms_per_cycle"] > 0
        assert cpu["all_nodes_cores"] == pytest.approx(sum(n["cores"] for n in cpu["nodes"].values()))
    write_realtime(tmp_path, rows, "assembly")
    assert format_cpu(rows) in (tmp_path / "realtime.md").read_text()
    assert [r["cpu"]["nodes"].keys() for r in json.loads((tmp_path / "realtime.json").read_text())] == \
        [r["cpu"]["nodes"].keys() for r in rows]


class FakeClock:
    """The clocks :func:`floor.probe` and :class:`CycleTiming` read, on a simulated time line: a sleep
    advances it, and so does each read of the thread's CPU time (by :attr:`STEP` of CPU and of wall
    time, a thread alone on its core). What a loop misses then follows from its period and its work
    alone, not from how busy the machine running the test is."""

    STEP = 1e-4

    def __init__(self) -> None:
        self.t, self.cpu = 1000.0, 0.0

    def monotonic(self) -> float:
        return self.t

    def monotonic_ns(self) -> int:
        return round(self.t * 1e9)

    def time_ns(self) -> int:
        return round(self.t * 1e9) + 1_700_000_000 * 10**9

    def sleep(self, seconds: float) -> None:
        self.t += max(0.0, seconds)

    def thread_time(self) -> float:
        self.cpu += self.STEP
        self.t += self.STEP
        return self.cpu


def test_floor_probe_counts_a_loop_that_overruns_as_the_controller_does(monkeypatch: pytest.MonkeyPatch) -> None:
    """On a simulated clock, 8 ms of CPU per 5 ms period: every cycle ends more than a period after it
    was due (CycleTiming counts one each) and each interval is over 1.5 periods (the lost periods count
    too); 1 ms per 5 ms: on time, nothing counted."""
    from dualarm_control.app.bench import floor
    from dualarm_control.ros import inputs

    clock = FakeClock()
    monkeypatch.setattr(floor, "time", clock)
    monkeypatch.setattr(inputs, "time", clock)
    over = floor.probe(0.005, 0.008, 0.3)
    lost = over["missed_deadlines"]  # of the simulated loop: no wall clock in this test
    assert over["cycles"] >= 2 and lost >= 2 * over["cycles"] - 1, over
    assert over["late_max_ms"] > 0.0
    within = floor.probe(0.005, 0.001, 0.3)
    on_time = {"missed_deadlines": 0, "missed_share": 0.0}
    assert within["cycles"] >= 60 and {k: within[k] for k in on_time} == on_time, within  # 0.3 s at 200 Hz
    assert within["late_max_ms"] == pytest.approx(0.0, abs=1e-6), within


def test_floor_probe_runs_in_its_own_process_and_says_whether_rt_was_granted() -> None:
    """One real probe (0.5 s): the row's figures, consistent with each other and as the bench's table shows
    them; how many deadlines it misses is the machine's."""
    from dualarm_control.app.bench.floor import format_floor, run_floor

    row = run_floor(200.0, 0.2, "none", "rt", seconds=0.5)
    assert set(row) == {"rate_hz", "load", "scheduling", "work_ms", "priority_granted", "cycles", "missed_deadlines",
                        "missed_share", "late_p50_ms", "late_p99_ms", "late_max_ms"}, row
    assert row["rate_hz"] == 200.0 and row["work_ms"] == 0.2 and row["scheduling"] == "rt" and row["load"] == "none"
    assert 1 <= row["cycles"] <= 101  # 0.5 s at 200 Hz, fewer when a wake-up was over a period late
    assert isinstance(row["priority_granted"], bool) and isinstance(row["missed_deadlines"], int)
    assert row["missed_deadlines"] >= 0, row  # a late cycle counts its lost periods too
    assert row["missed_share"] == pytest.approx(row["missed_deadlines"] / row["cycles"]), row
    assert 0.0 <= row["late_p50_ms"] <= row["late_p99_ms"] <= row["late_max_ms"] + 1e-9, row  # a distribution
    (line,) = format_floor([row]).splitlines()[2:]
    sched = "rt" if row["priority_granted"] else "rt (not permitted)"
    assert line == (f"| 200 | none | {sched} | 0.200 | {row['cycles']} | {row['missed_deadlines']} "
                    f"({row['missed_share']:.2%}) | {row['late_p50_ms']:.3f} / {row['late_p99_ms']:.3f} / "
                    f"{row['late_max_ms']:.2f} |"), line


def test_floor_rows_take_the_leanest_launch_of_each_group(monkeypatch: pytest.MonkeyPatch) -> None:
    from dualarm_control.app.bench import floor

    calls: list[tuple[float, float, str, str]] = []
    monkeypatch.setattr(floor, "run_floor", lambda rate, work, load, sched, seconds: calls.append(
        (rate, work, load, sched)) or {"rate_hz": rate})
    rows = [{"rate_hz": 200.0, "load": "busy", "scheduling": "normal", "cpu": {"all_nodes_ms_per_cycle": 2.5}},
            {"rate_hz": 200.0, "load": "busy", "scheduling": "normal", "cpu": {"all_nodes_ms_per_cycle": 1.4}},
            {"rate_hz": 1000.0, "cpu": {"all_nodes_ms_per_cycle": 0.9}},
            {"rate_hz": 1000.0, "cpu": {}}]
    assert len(floor.floor_rows(rows, seconds=1.0)) == 2
    assert calls == [(200.0, 1.4, "busy", "normal"), (1000.0, 0.9, "none", "rt")]


def test_floor_belongs_to_realtime(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "--floor", "--output", str(tmp_path)]) == 2
    assert "--floor belongs to --realtime" in capsys.readouterr().err
