"""ROS command-line parsing (--ros-args), names and parameter typing, without DDS traffic."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from dualarm_control.ros import dds_env, names
from dualarm_control.ros.args import (
    RosArgsError,
    load_params_file,
    node_pattern_matches,
    parse_ros_args,
    parse_value,
    remove_ros_args,
)
from dualarm_control.ros.parameters import (
    InvalidParameterTypeException,
    ParameterNotDeclaredException,
    ParameterStore,
)

PARAMS = """\
/**:
  ros__parameters:
    rate_hz: 100.0
    solver: standard_qp
controller_node:
  ros__parameters:
    rate_hz: 200.0
    gains:
      k: 10.0
      alpha: 0.1
    joints: [a, b]
    limits: [1.0, 2.0]
    enabled: true
    count: 3
other_node:
  ros__parameters:
    rate_hz: 50.0
/arms/left_node:
  ros__parameters:
    side: left
"""


@pytest.fixture
def params_file(tmp_path: Path) -> Path:
    path = tmp_path / "params.yaml"
    path.write_text(PARAMS)
    return path


def test_params_file_sections_wildcard_and_node(params_file: Path) -> None:
    args = parse_ros_args(["prog", "--ros-args", "--params-file", str(params_file)])
    ctl = args.parameter_overrides("/controller_node")
    assert ctl == {
        "rate_hz": 200.0, "solver": "standard_qp", "gains.k": 10.0, "gains.alpha": 0.1,
        "joints": ["a", "b"], "limits": [1.0, 2.0], "enabled": True, "count": 3,
    }
    assert args.parameter_overrides("/other_node") == {"rate_hz": 50.0, "solver": "standard_qp"}
    # a plain node name means the root namespace, like rcl
    assert args.parameter_overrides("/ns/controller_node") == {"rate_hz": 100.0, "solver": "standard_qp"}
    assert args.parameter_overrides("/arms/left_node")["side"] == "left"
    assert args.parameter_sources("/controller_node")["rate_hz"] == str(params_file)


def test_cli_order_later_wins(params_file: Path) -> None:
    args = parse_ros_args(
        ["prog", "--ros-args", "-p", "rate_hz:=300.0", "--params-file", str(params_file), "-p", "count:=7"]
    )
    over = args.parameter_overrides("/controller_node")
    assert over["rate_hz"] == 200.0  # the file came after the first -p
    assert over["count"] == 7


@pytest.mark.parametrize(
    ("text", "value"),
    [
        ("200.0", 200.0), ("200", 200), ("true", True), ("False", False), ("sparse_qp", "sparse_qp"),
        ("'200'", "200"), ("[1.0, 2.5]", [1.0, 2.5]), ("[a, b]", ["a", "b"]), ("1e-3", 1e-3), ("-2.5E2", -250.0),
    ],
)
def test_p_values_typed_like_ros(text: str, value: object) -> None:
    got = parse_value(text)
    assert got == value and type(got) is type(value)
    args = parse_ros_args(["prog", "--ros-args", "-p", f"x:={text}"])
    assert args.parameter_overrides("/any/node") == {"x": value}


def test_mixed_list_rejected() -> None:
    with pytest.raises(RosArgsError, match="mixes integers and floats"):
        parse_value("[1, 2.0]")


def test_remaps_node_ns_and_non_ros_args() -> None:
    argv = [
        "prog", "--mode", "fast", "--ros-args", "-r", "__node:=ctl", "-r", "__ns:=/cell",
        "-r", "joint_states:=/sim/joint_states", "-r", "other_node:cmd:=/x", "--log-level", "debug", "--",
        "tail",
    ]
    args = parse_ros_args(argv)
    assert args.non_ros_args == ["prog", "--mode", "fast", "tail"]
    assert remove_ros_args(argv) == ["prog", "--mode", "fast", "tail"]
    assert args.node_name_override("controller_node") == "ctl"
    assert args.namespace_override("controller_node") == "/cell"
    rules = [(r.src, r.dst) for r in args.topic_remaps("controller_node")]
    assert rules == [("joint_states", "/sim/joint_states")]
    assert [(r.src, r.dst) for r in args.topic_remaps("other_node")][-1] == ("cmd", "/x")
    assert args.log_levels == {"": "debug"}
    resolved = names.remap_topic_name("joint_states", "ctl", "/cell", rules)
    assert resolved == "/sim/joint_states"
    assert names.dds_topic_name(resolved) == "rt/sim/joint_states"


def test_topic_name_expansion() -> None:
    assert names.expand_topic_name("joint_states", "n", "/") == "/joint_states"
    assert names.expand_topic_name("joint_states", "n", "/cell") == "/cell/joint_states"
    assert names.expand_topic_name("/joint_states", "n", "/cell") == "/joint_states"
    assert names.expand_topic_name("~/status", "n", "/cell") == "/cell/n/status"
    assert names.expand_topic_name("{node}/cmd", "n", "/") == "/n/cmd"
    with pytest.raises(names.InvalidNameError, match="9lives"):
        names.expand_topic_name("9lives", "n", "/")
    with pytest.raises(names.InvalidNameError):
        names.validate_node_name("bad-name")


def test_node_patterns() -> None:
    assert node_pattern_matches("/**", "/a/b/node")
    assert node_pattern_matches("/**/node", "/node")
    assert node_pattern_matches("/*/node", "/a/node")
    assert not node_pattern_matches("/*/node", "/node")
    assert not node_pattern_matches("/node", "/a/node")


def test_malformed_yaml_clear_error(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("controller_node:\n  ros__parameters:\n    rate_hz: [1.0, 2.0\n")
    with pytest.raises(RosArgsError, match=r"bad\.yaml: malformed YAML.*line"):
        parse_ros_args(["prog", "--ros-args", "--params-file", str(bad)])


def test_params_file_structure_errors(tmp_path: Path) -> None:
    flat = tmp_path / "flat.yaml"
    flat.write_text("rate_hz: 200.0\n")
    with pytest.raises(RosArgsError, match="'rate_hz' is not a node section"):
        load_params_file(flat)
    missing = tmp_path / "missing.yaml"
    with pytest.raises(RosArgsError, match="cannot read"):
        load_params_file(missing)
    with pytest.raises(RosArgsError, match="unknown ROS argument '--bogus'"):
        parse_ros_args(["prog", "--ros-args", "--bogus"])
    with pytest.raises(RosArgsError, match="needs a value"):
        parse_ros_args(["prog", "--ros-args", "-p"])


def test_parameter_type_mismatch_messages() -> None:
    store = ParameterStore("controller_node", {"rate_hz": 200, "solver": 3, "gains": [1, 2], "extra": 1.0},
                           {"rate_hz": "--params-file cfg.yaml"})
    with pytest.raises(InvalidParameterTypeException) as err:
        store.declare("rate_hz", 200.0)
    text = str(err.value)
    assert "controller_node.rate_hz" in text and "200" in text and "double" in text
    assert "write 200.0, not 200" in text and "cfg.yaml" in text
    with pytest.raises(InvalidParameterTypeException, match=r"solver.*got 3.*type string.*not integer"):
        store.declare("solver", "sparse_qp")
    with pytest.raises(InvalidParameterTypeException, match=r"write \[1\.0, 2\.0\], not \[1, 2\]"):
        store.declare("gains", [0.0, 0.0])
    assert store.undeclared_overrides() == {"rate_hz": 200, "solver": 3, "gains": [1, 2], "extra": 1.0}
    assert store.declare("extra", 0.5).value == 1.0
    assert store.declare("free", None).value is None
    with pytest.raises(ParameterNotDeclaredException, match="'nope'.*not declared"):
        store.get("nope")


def test_loopback_default_respects_user_settings() -> None:
    env: dict[str, str] = {}
    dds_env.apply_loopback_default(env)
    uri = env["CYCLONEDDS_URI"]
    assert uri.startswith("file://") and uri.endswith("config/cyclonedds_loopback.xml")
    xml = Path(uri[len("file://"):]).read_text()
    for needle in ('<NetworkInterface name="lo"/>', "<AllowMulticast>false</AllowMulticast>",
                   '<Peer address="127.0.0.1"/>', "<ParticipantIndex>auto</ParticipantIndex>",
                   "<MaxAutoParticipantIndex>50</MaxAutoParticipantIndex>"):
        assert needle in xml
    user = {"CYCLONEDDS_URI": "<CycloneDDS/>"}
    dds_env.apply_loopback_default(user)
    assert user == {"CYCLONEDDS_URI": "<CycloneDDS/>"}
    ranged = {"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"}
    dds_env.apply_loopback_default(ranged)
    assert "CYCLONEDDS_URI" not in ranged
    assert dds_env.domain_id({"ROS_DOMAIN_ID": "42"}) == 42
    with pytest.raises(ValueError, match="ROS_DOMAIN_ID"):
        dds_env.domain_id({"ROS_DOMAIN_ID": "x"})
    # importing the package applied it to this process
    assert os.environ.get("CYCLONEDDS_URI")
