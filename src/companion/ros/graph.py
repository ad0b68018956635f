"""What the node checks on the ROS graph: a publisher on one of its input topics whose type it
does not take, or whose QoS cannot match its subscription, would otherwise mean silence (the
robot never moves). Each problem is one line naming the topic, the publisher's type or QoS,
and the setting that would accept it. Pure functions: the transport lists the publishers.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass

from companion.ros.convert import PERSON_TYPES, person_types
from companion.ros.settings import RosParams
from companion.ros.transport import Endpoint, Qos


@dataclass(frozen=True)
class Input:
    """One input of the node: its topic, its key under ``ros.topics`` and ``ros.qos``
    (``'odom'``), the message types it takes, and its subscription's QoS."""

    topic: str
    key: str
    types: tuple[str, ...]
    qos: Qos


def type_problem(inp: Input, msgtype: str, readable: dict[str, str],
                 setting: str) -> str | None:
    """The line for a publisher of ``msgtype`` on ``inp`` (None if the node takes it).
    ``readable`` maps the types the node could take with another ``setting`` (for the person,
    ``ros.person_type``) to that setting's value."""
    if msgtype in inp.types:
        return None
    if msgtype in readable:
        return (f"{inp.topic}: a publisher sends {msgtype}, which {setting} "
                f"{readable.get(inp.types[0], '?')!r} does not take; set {setting}: "
                f"{readable[msgtype]} (or auto)")
    return (f"{inp.topic}: a publisher sends {msgtype}, which companion does not read as "
            f"ros.topics.{inp.key}; it takes {' or '.join(inp.types)} (set ros.topics."
            f"{inp.key} to a topic of that type)")


def qos_problem(inp: Input, offered: Qos) -> str | None:
    """The line for a publisher whose offered QoS cannot match ``inp``'s subscription (None if
    it matches): a reliable subscription and a best-effort publisher, or a transient-local
    subscription and a volatile publisher (DDS's requested-incompatible-QoS rules)."""
    if inp.qos.reliable and not offered.reliable:
        return (f"{inp.topic}: a publisher offers best-effort delivery and ros.qos.{inp.key}."
                f"reliability is 'reliable' (incompatible QoS: nothing arrives); set ros.qos."
                f"{inp.key}.reliability: best_effort")
    if inp.qos.transient_local and not offered.transient_local:
        return (f"{inp.topic}: a publisher offers volatile durability and ros.qos.{inp.key}."
                f"durability is 'transient_local' (incompatible QoS: nothing arrives); set "
                f"ros.qos.{inp.key}.durability: volatile")
    return None


def problems(inputs: Iterable[Input], publishers: dict[str, list[Endpoint]],
             readable: dict[str, str], setting: str) -> list[str]:
    """Every problem of every input, given the publishers on each input's topic (one line per
    kind of problem, in the order of ``inputs``)."""
    out: list[str] = []
    for inp in inputs:
        for pub in publishers.get(inp.topic, []):
            line = type_problem(inp, pub.msgtype, readable if inp.key == "person" else {},
                                setting)
            if line is None and pub.msgtype in inp.types:
                line = qos_problem(inp, pub.qos)
            if line is not None and line not in out:
                out.append(line)
    return out


def node_inputs(ros: RosParams) -> list[Input]:
    """The node's inputs: odometry, the scan (unless ``ros.topics.scan`` is empty), people."""
    t, q = ros.topics, ros.qos
    inputs = [Input(t.odom, "odom", ("nav_msgs/msg/Odometry",), q.odom.qos())]
    if t.scan:
        inputs.append(Input(t.scan, "scan", ("sensor_msgs/msg/LaserScan",), q.scan.qos()))
    inputs.append(Input(t.person, "person", person_types(ros.person_type), q.person.qos()))
    return inputs


def input_problems(ros: RosParams, publishers: Callable[[str], list[Endpoint]]) -> list[str]:
    """Every problem on the node's inputs, given ``publishers(topic)`` (a transport's)."""
    inputs = node_inputs(ros)
    readable = {msgtype: kind for kind, msgtype in PERSON_TYPES.items()}
    return problems(inputs, {i.topic: publishers(i.topic) for i in inputs}, readable,
                    "ros.person_type")
