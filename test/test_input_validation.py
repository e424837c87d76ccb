"""Input validation (issue 11): the checks between a received message and the solver, one case each.

Unit tests on the conversion and guard functions the nodes call (dualarm_control.ros.convert,
dualarm_control.ros.inputs) and on the reach bound of the model; the real-process case is
test_fuzz.py::test_garbled_cdr_and_bad_messages_on_running_nodes.
"""

from __future__ import annotations

import re
from types import SimpleNamespace

import numpy as np
import pytest

from dualarm_control.errors import InputRejected
from dualarm_control.kinematics import DualArmModel
from dualarm_control.ros import convert
from dualarm_control.ros.inputs import StampGate, Throttle

NS = convert.NS


@pytest.fixture(scope="module")
def model() -> DualArmModel:
    return DualArmModel()


@pytest.fixture(scope="module")
def order(model: DualArmModel) -> dict[str, int]:
    return {name: i for i, name in enumerate(model.joint_names)}


def joint_state(names: list[str], position: list[float], velocity: list[float] | None = None) -> SimpleNamespace:
    return SimpleNamespace(name=names, position=position, velocity=velocity if velocity is not None else [])


# ---- joint states -------------------------------------------------------------------------------


def test_joint_order_is_mapped_by_name(order: dict[str, int]) -> None:
    """Reversed order plus an extra joint: values land on the right joints, the extra one is ignored."""
    names = list(order)
    q = np.arange(14) * 0.1
    msg = joint_state([*reversed(names), "gripper"], [*reversed(q.tolist()), 9.0], [*reversed((q * 2).tolist()), 0.0])
    decoded = convert.JointStateInput(order).message_vectors(msg)
    np.testing.assert_array_equal(decoded[0], q)
    np.testing.assert_array_equal(decoded[1], 2 * q)


@pytest.mark.parametrize(("edit", "fragment"), [
    (lambda n, q, v: (n[:-1], q[:-1], v[:-1]), "missing 1 of the 14 joints"),
    (lambda n, q, v: ([f"x{i}" for i in range(14)], q, v), "missing 14 of the 14 joints"),
    (lambda n, q, v: ([n[0], *n[1:-1], n[0]], q, v), "duplicate joint names ['left_joint_1']"),
    (lambda n, q, v: (n, q[:-1], v), "14 names but 13 positions"),
    (lambda n, q, v: (n, q, v[:5]), "14 names but 14 positions and 5 velocities"),
    (lambda n, q, v: (n, [np.nan, *q[1:]], v), "NaN or inf"),
    (lambda n, q, v: (n, q, [*v[:-1], -np.inf]), "NaN or inf"),
])
def test_unusable_joint_states_are_rejected_with_the_reason(order: dict[str, int], edit, fragment: str) -> None:
    """Missing, unknown or duplicate names, wrong counts, NaN/inf: InputRejected with the reason, never arrays."""
    names, q, v = edit(list(order), [0.0] * 14, [0.0] * 14)
    with pytest.raises(InputRejected, match=re.escape(fragment)) as caught:
        convert.JointStateInput(order).message_vectors(joint_state(names, q, v))
    assert caught.value.reason == str(caught.value) and caught.value.field in ("name", "position", "velocity")


def test_a_rejected_joint_state_carries_its_stamp_and_the_names_are_mapped_again(order: dict[str, int]) -> None:
    """The stamp of the rejected message is on the exception; a good message with the same names after
    a bad one (the partial topic's mapping) decodes."""
    names = list(order)
    decoder = convert.JointStateInput(order)
    bad = SimpleNamespace(name=names[:-1], position=[0.0] * 13, velocity=[],
                          header=SimpleNamespace(stamp=SimpleNamespace(sec=3, nanosec=4)))
    with pytest.raises(InputRejected, match="missing 1 of the 14 joints") as caught:
        decoder.from_message(bad)
    assert caught.value.stamp == 3 * NS + 4 and caught.value.value == [names[-1]]
    assert decoder.names == tuple(names[:-1])
    good = SimpleNamespace(name=names, position=[0.1] * 14, velocity=[], header=bad.header)
    np.testing.assert_array_equal(decoder.from_message(good)[1][0], np.full(14, 0.1))


def test_a_payload_decoded_again_gives_the_kept_answer_and_a_new_one_is_read(order: dict[str, int]) -> None:
    """The nodes of one process share a decoder (LocalBus.shared) and get the same bytes object: it is read once,
    its arrays read-only; a rejected payload is rejected again with the same error; equal bytes in another
    object are read again."""
    names = list(order)
    decoder = convert.JointStateInput(order)
    reads = []
    read = decoder.read
    decoder.read = lambda data: reads.append(data) or read(data)  # type: ignore[method-assign]
    data = convert.joint_state(names, 5, np.full(14, 0.1), np.zeros(14))
    first = decoder.from_bytes(data)
    assert decoder.from_bytes(data) is first and len(reads) == 1
    assert first[0] == 5 and not first[1][0].flags.writeable and not first[1][1].flags.writeable
    with pytest.raises(ValueError):
        first[1][0][0] = 1.0
    decoder.from_bytes(bytes(bytearray(data)))
    assert len(reads) == 2
    bad = convert.joint_state(names, 6, np.full(14, np.nan), np.zeros(14))
    with pytest.raises(InputRejected, match="NaN") as caught:
        decoder.from_bytes(bad)
    with pytest.raises(InputRejected) as again:
        decoder.from_bytes(bad)
    assert again.value is caught.value and again.value.stamp == 6 and len(reads) == 3


def test_joint_state_without_velocities_gives_zero_velocities(order: dict[str, int]) -> None:
    decoded = convert.JointStateInput(order).message_vectors(joint_state(list(order), [0.2] * 14))
    np.testing.assert_array_equal(decoded[1], np.zeros(14))


def test_joint_reference_checks_names_counts_and_values(order: dict[str, int]) -> None:
    """/joint_reference shares the name mapping: duplicates and wrong counts rejected, order mapped."""
    names = list(order)

    def message(joint_names: list[str], positions: list[float]) -> SimpleNamespace:
        point = SimpleNamespace(positions=positions, velocities=[0.0] * len(positions))
        return SimpleNamespace(joint_names=joint_names, points=[point], header=SimpleNamespace(
            stamp=SimpleNamespace(sec=1, nanosec=0)))

    ok = convert.joint_reference(message(names[::-1], list(range(14))[::-1]), order)
    assert ok[0] == NS
    np.testing.assert_array_equal(ok[1], np.arange(14))
    with pytest.raises(InputRejected, match="duplicate") as caught:
        convert.joint_reference(message([names[1], *names[1:]], [0.0] * 14), order)
    assert caught.value.stamp == NS
    with pytest.raises(InputRejected, match="13 positions"):
        convert.joint_reference(message(names, [0.0] * 13), order)


# ---- commands (sim_node) ------------------------------------------------------------------------


def test_commands_with_wrong_length_or_non_finite_values_are_rejected() -> None:
    with pytest.raises(InputRejected, match=r"^command with 13 values rejected: expected 14$"):
        convert.CommandInput(14).from_message(SimpleNamespace(data=[0.0] * 13))
    with pytest.raises(InputRejected, match=re.escape("NaN or inf at indices [3]")) as caught:
        convert.CommandInput(14).from_message(SimpleNamespace(data=[0.0] * 3 + [np.nan] + [0.0] * 10))
    assert caught.value.stamp is None and caught.value.value.shape == (14,)
    good = convert.CommandInput(14).from_message(SimpleNamespace(data=[0.5] * 14))
    np.testing.assert_array_equal(good, np.full(14, 0.5))


# ---- targets ------------------------------------------------------------------------------------


def target(position: list[float], quaternion: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)
           ) -> SimpleNamespace:
    vec = SimpleNamespace
    transform = vec(translation=vec(x=position[0], y=position[1], z=position[2]),
                    rotation=vec(x=quaternion[0], y=quaternion[1], z=quaternion[2], w=quaternion[3]))
    twist = vec(linear=vec(x=0.0, y=0.0, z=0.0), angular=vec(x=0.0, y=0.0, z=0.0))
    point = vec(transforms=[transform], velocities=[twist])
    return vec(points=[point], header=vec(stamp=vec(sec=2, nanosec=5)))


def test_relative_reach_bounds_every_configuration(model: DualArmModel) -> None:
    """The documented bound (2.870 m for the cell) is >= ||p_r|| at 2000 random configurations."""
    reach = model.relative_reach()
    assert reach == pytest.approx(2.8697, abs=1e-3)
    rng = np.random.default_rng(3)
    distances = [np.linalg.norm(model.relative_pose(rng.uniform(model.q_min, model.q_max))[0]) for _ in range(2000)]
    assert max(distances) < reach


def test_target_beyond_the_reach_is_rejected(model: DualArmModel) -> None:
    reach = model.relative_reach()
    inside = convert.TargetInput(reach).from_message(target([0.0, 0.0, 0.5]))[1]
    assert inside.stamp_ns == 2 * NS + 5
    with pytest.raises(InputRejected, match=r"3\.000 m .*reach 2\.870 m") as caught:
        convert.TargetInput(reach).from_message(target([3.0, 0.0, 0.0]))
    assert caught.value.stamp == 2 * NS + 5 and caught.value.value == pytest.approx(3.0)


@pytest.mark.parametrize("bad", [
    target([np.nan, 0.0, 0.0]), target([0.0, 0.0, 0.0], (0.0, 0.0, 0.0, 0.0)),
    target([0.0, 0.0, 0.0], (np.inf, 0.0, 0.0, 1.0)),
])
def test_non_finite_targets_or_zero_quaternions_are_rejected(bad: SimpleNamespace) -> None:
    with pytest.raises(InputRejected, match="NaN or inf"):
        convert.TargetInput(2.87).from_message(bad)


def test_target_with_several_points_is_rejected() -> None:
    msg = target([0.0, 0.0, 0.0])
    msg.points = msg.points * 2
    with pytest.raises(InputRejected, match="exactly one point"):
        convert.TargetInput().from_message(msg)


# ---- stamps -------------------------------------------------------------------------------------


def test_stamps_newer_or_equal_are_accepted_older_rejected() -> None:
    gate = StampGate("joint_states")
    assert gate.check(10 * NS).accepted and gate.check(10 * NS).accepted and gate.check(11 * NS).accepted
    verdict = gate.check(5 * NS)
    assert not verdict.accepted and "older than the last accepted 11.000 s" in verdict.message
    assert gate.check(12 * NS).accepted  # the stream goes on: the older sample was a stray one


def test_a_restarted_time_source_is_accepted_after_three_monotonic_older_stamps() -> None:
    """A simulator restarted at t=0: two samples rejected, the third accepted with "time source restarted"."""
    gate = StampGate("joint_states")
    for k in range(100, 110):
        assert gate.check(k * NS // 100).accepted
    verdicts = [gate.check(k * 5_000_000) for k in range(3)]
    assert [v.accepted for v in verdicts] == [False, False, True]
    assert "time source restarted" in verdicts[2].message
    assert gate.check(15_000_000).accepted and gate.last == 15_000_000


def test_older_stamps_that_are_not_monotonic_do_not_restart_the_time_base() -> None:
    """Older stamps that jump around (50, 40, 45, 30, 20, 21) are all rejected; a third monotonic one (22) restarts."""
    gate = StampGate("relative_target")
    gate.check(100 * NS)
    assert [gate.check(s * NS).accepted for s in (50, 40, 45, 30, 20, 21)] == [False] * 6
    assert gate.check(22 * NS).accepted and gate.last == 22 * NS


def test_throttle_lets_one_message_per_interval_through_and_counts_the_rest() -> None:
    throttle = Throttle(60.0)
    assert throttle.text("first") == "first"
    assert throttle.text("second") is None and throttle.text("third") is None
    throttle._last -= 61.0
    assert throttle.text("fourth") == "fourth (2 similar messages suppressed)"
