"""Notes the package's recorder leaves in a bag: ``custom_data`` entries of metadata.yaml whose key
starts with ``dualarm.`` (e.g. that /tf was computed from /joint_states, ``ros/computed_tf.NOTE``).
``dualarm bag info`` prints them after the summary."""

from __future__ import annotations

from pathlib import Path

NOTE_PREFIX = "dualarm."


def bag_notes(path: Path) -> list[str]:
    """The recorder's notes in the bag directory ``path``, sorted by key ([] without metadata.yaml)."""
    import yaml

    meta_file = Path(path) / "metadata.yaml"
    if not meta_file.is_file():
        return []
    data = yaml.safe_load(meta_file.read_text()) or {}
    info = data.get("rosbag2_bagfile_information", {}) if isinstance(data, dict) else {}
    custom = (info.get("custom_data") if isinstance(info, dict) else None) or {}
    return [str(value) for key, value in sorted(custom.items()) if str(key).startswith(NOTE_PREFIX)]


def format_notes(path: Path) -> str:
    """``bag info``'s lines for the notes ('' without any), in its column layout."""
    return "\n".join(f"{'Note:':<19}{note}" for note in bag_notes(path))
