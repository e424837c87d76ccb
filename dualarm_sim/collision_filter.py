"""Which link pairs of a simulated cell make contact: pybullet's collision filter.

* Contacts between the arms (issue 27, docs/collision.md "The simulator's contacts"): a robot's
cell (:meth:`CellConfig.for_robot`) is loaded with self-collision (``URDF_USE_SELF_COLLISION``)
and every link pair is filtered out (``setCollisionFilterPair``) but ``CellConfig.collision_pairs``:
the link pairs the controller's collision model checks (:func:`robot_collision_pairs`: left arm
against right arm, an arm against the fixed parts and against its own links at joint distance
>= 3, minus the robot's ``collision_allowed`` pairs, the scenario's allowed pairs (``allowed`` of
:meth:`CellConfig.for_robot`: the assembly's tools, which meet on purpose) and the broadphase's far
pairs), so that adjacent links and shapes that overlap by design never touch. The two end effectors
(the tools' bodies, config/tools/) collide like any other links unless the scenario allows them
(issue 40: no robot-wide allowance between the arms). :meth:`DualArmCell.contacts` reads the link pairs in contact after
a step (one ``getContactPoints`` call). When nothing touches, the physics is the same as
without self-collision, bit for bit: contact points farther apart than 0 (within pybullet's
contact threshold) give zero impulses (test_sim_contacts.py; the shipped robots' assemblies and
pan cleaning compared so: docs/collision.md).
``CellConfig()`` alone (a URDF, no robot description) has no collision pairs.
* Contacts between links of the cell can be switched on pair by pair
(``CellConfig.contact_pairs``, e.g. the brush on the pan of the pan-cleaning cell): the
URDF is then loaded with self-collision and every other link pair (but the collision pairs) is
filtered out. These intended contacts are not counted by :meth:`DualArmCell.contacts`.
Contact stiffness/damping/friction come from the URDF's ``<contact>`` tags.
"""

from __future__ import annotations

import pybullet as p

from dualarm_sim.cell_config import CellConfig

Pair = tuple[str, str]


def _pair_indices(link_index: dict[str, int], pair: Pair, what: str, urdf: str) -> tuple[int, int]:
    """The pybullet link indices of a link pair, smaller first (ValueError naming an unknown link)."""
    for name in pair:
        if name not in link_index:
            raise ValueError(f"{what}: unknown link {name!r} in {urdf}")
    a, b = link_index[pair[0]], link_index[pair[1]]
    return min(a, b), max(a, b)


def filter_link_pairs(body: int, client: int, link_index: dict[str, int], config: CellConfig,
                      n_links: int) -> dict[tuple[int, int], Pair]:
    """Filter out every link pair of ``body`` (loaded with self-collision) but ``config.contact_pairs`` and
    ``config.collision_pairs``; the counted pairs (the collision pairs that are not intended contacts) by
    their link indices, smaller first."""
    urdf = config.urdf.name
    intended = {_pair_indices(link_index, pair, "contact_pairs", urdf) for pair in config.contact_pairs}
    counted: dict[tuple[int, int], Pair] = {}
    for pair in config.collision_pairs:
        ab = _pair_indices(link_index, pair, "collision_pairs", urdf)
        if ab not in intended:
            counted[ab] = (pair[0], pair[1])
    keep = intended | set(counted)
    # only links with collision shapes: a link without has no collider, so no filter of its pairs
    # is ever consulted (Baxter: 666 of 1711 pairs; each call costs ~0.1 ms)
    shaped = [i for i in range(-1, n_links) if p.getCollisionShapeData(body, i, physicsClientId=client)]
    for k, i in enumerate(shaped):
        for j in shaped[k + 1:]:
            p.setCollisionFilterPair(body, body, i, j, int((i, j) in keep), physicsClientId=client)
    return counted
