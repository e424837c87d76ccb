"""ROS 2 graph information on ``ros_discovery_info``, so ``ros2 node list`` sees our nodes.

rmw_cyclonedds_cpp publishes, per participant (= per process context), a
``rmw_dds_common/msg/ParticipantEntitiesInfo`` on the DDS topic ``ros_discovery_info``
(no ``rt/`` prefix): the participant GID and, per node, its namespace, name and the
GIDs of its readers and writers. A GID is the entity's 16-byte DDS GUID. The QoS is
reliable, transient-local, keep-last 1, XCDR1. Topics interoperate without this;
it only names the nodes in ROS tools.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from cyclonedds.core import Entity, Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from dualarm_control.ros.msgs import Gid, NodeEntitiesInfo, ParticipantEntitiesInfo

DISCOVERY_TOPIC = "ros_discovery_info"


def gid_of(entity: Entity) -> Gid:
    """The ROS GID (16-byte DDS GUID) of a participant, reader or writer."""
    return Gid(data=entity.get_guid().bytes)


def discovery_qos() -> Qos:
    """rmw_cyclonedds_cpp's QoS for the graph writer."""
    keep_last_1 = Policy.History.KeepLast(depth=1)
    return Qos(
        Policy.Reliability.Reliable(max_blocking_time=duration(infinite=True)),
        Policy.Durability.TransientLocal,
        keep_last_1,
        Policy.DurabilityService(
            cleanup_delay=0, history=keep_last_1, max_samples=-1, max_instances=-1, max_samples_per_instance=-1
        ),
        Policy.WriterDataLifecycle(autodispose=False),
        Policy.DataRepresentation(use_cdrv0_representation=True),
    )


@dataclass
class NodeEntities:
    """The readers and writers of one node, for the graph message."""

    namespace: str
    name: str
    readers: list[Any] = field(default_factory=list)
    writers: list[Any] = field(default_factory=list)

    def to_msg(self) -> NodeEntitiesInfo:
        """As rmw_dds_common/NodeEntitiesInfo."""
        return NodeEntitiesInfo(
            node_namespace=self.namespace, node_name=self.name,
            reader_gid_seq=[gid_of(r) for r in self.readers],
            writer_gid_seq=[gid_of(w) for w in self.writers],
        )


class GraphPublisher:
    """Publishes this participant's nodes and their endpoints on ``ros_discovery_info``."""

    def __init__(self, participant: DomainParticipant) -> None:
        self._participant = participant
        self._gid = gid_of(participant)
        self._topic = Topic(participant, DISCOVERY_TOPIC, ParticipantEntitiesInfo)
        self._writer = DataWriter(participant, self._topic, qos=discovery_qos())

    @property
    def writer(self) -> DataWriter:
        """The underlying DataWriter (for tests)."""
        return self._writer

    def publish(self, nodes: list[NodeEntities]) -> ParticipantEntitiesInfo:
        """Publish the current graph of this participant; returns the message sent."""
        msg = ParticipantEntitiesInfo(gid=self._gid, node_entities_info_seq=[n.to_msg() for n in nodes])
        self._writer.write(msg)
        return msg
