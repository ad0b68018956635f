"""``companion replay``: a recorded bag's inputs through the node, open loop (docs/recording.md).

The odometry, scan and person messages of a rosbag2 bag (sqlite3 or MCAP) go to a
:class:`~companion.ros.node.CompanionNode` in log-time order; the node ticks at the recorded
tick times (the header stamps of /companion/status, else of a TwistStamped /cmd_vel, else every
period from the first input), each after every input logged up to it. The replayed bag holds
the inputs, what the node published, the scene, and the recorded command as
``/cmd_vel_recorded``. The node's parameters are ``--params``, else those a companion
recording stored in the bag, else the defaults with the side read from the data
(:mod:`companion.ros.infer`). Every problem with the bag is a one-line ConfigError naming the
bag and the topic or record.
"""

from __future__ import annotations

import json
import math
from collections import defaultdict
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from companion import metrics
from companion.errors import ConfigError
from companion.model import relative_state
from companion.ros import convert
from companion.ros.bag import BagWriter
from companion.ros.convert import TimeBase, person_types
from companion.ros.messages import typestore
from companion.ros.parameters import config_mapping
from companion.ros.record import CUSTOM_KEY, RecordedNode, open_bag
from companion.ros.settings import NodeConfig, config_from_mapping
from companion.ros.transport import MemoryBus, MemoryTransport
from companion.types import Log

RECORDED_SUFFIX = "_recorded"
_TWISTS = ("geometry_msgs/msg/Twist", "geometry_msgs/msg/TwistStamped")


class BagReader:
    """A bag opened for replay; its errors are ConfigErrors naming the bag."""

    def __init__(self, path: Path, typestore: Any = None):
        from rosbags.rosbag2 import Reader

        self.path, self.typestore = path, typestore
        if not path.exists():
            raise ConfigError(f"{path}: no such bag")
        try:
            self.reader = Reader(path)
            self.reader.open()
        except Exception as exc:   # rosbags raises several kinds for a damaged bag
            raise ConfigError(f"{path}: not a readable rosbag2 bag "
                              f"({_first_line(exc)})") from None
        self.by_topic: dict[str, list[Any]] = defaultdict(list)
        for c in self.reader.connections:
            self.by_topic[c.topic].append(c)
        self.topics = {topic: cs[0] for topic, cs in self.by_topic.items()}
        if self.reader.message_count == 0:
            self.close()
            raise ConfigError(f"{path}: empty bag (no messages)")

    def recorded_config(self) -> dict[str, Any] | None:
        """The node parameters a companion recording stored, or None."""
        meta = getattr(self.reader.storage, "metadata", None)    # a folder's metadata.yaml
        custom = getattr(meta, "custom", None) or {}
        text = custom.get(CUSTOM_KEY)
        return json.loads(text) if text else None

    def connections(self, topic: str) -> list[Any]:
        return self.by_topic.get(topic, [])

    def connection(self, topic: str, types: tuple[str, ...], what: str) -> list[Any]:
        """The connections of ``topic`` of the ``types`` the node takes (at least one)."""
        cs = self.by_topic.get(topic)
        if not cs:
            raise ConfigError(f"{self.path}: topic {topic} ({what}): not in the bag; it has "
                              f"{', '.join(sorted(self.topics)) or 'no topics'}")
        ours = [c for c in cs if c.msgtype in types]
        if not ours:
            raise ConfigError(f"{self.path}: topic {topic}: message type "
                              f"{', '.join(c.msgtype for c in cs)}, expected "
                              f"{' or '.join(types)} ({what})")
        return ours

    def messages(self, connections: list[Any]) -> Iterator[tuple[str, int, Any]]:
        """(topic, log time ns, message) in log-time order; a record that cannot be read or
        decoded is a ConfigError naming it."""
        for c, t, msg in self.records(connections):
            yield c.topic, t, msg

    def records(self, connections: list[Any]) -> Iterator[tuple[Any, int, Any]]:
        """(connection, log time ns, message) in log-time order (see :meth:`messages`)."""
        ts = self.typestore or typestore()
        count = 0
        seen = dict.fromkeys((c.id for c in connections), 0)
        it = self.reader.messages(connections=connections)
        while True:
            try:
                c, t, data = next(it)
            except StopIteration:
                for c in connections:     # fewer messages than the bag's index: damaged
                    if seen[c.id] != c.msgcount:
                        raise ConfigError(
                            f"{self.path}: topic {c.topic}: {seen[c.id]} of the "
                            f"{c.msgcount} messages the bag lists could be read; a record is "
                            f"truncated or corrupt") from None
                return
            except Exception as exc:
                raise ConfigError(f"{self.path}: record after message {count} cannot be read "
                                  f"({_first_line(exc)}); truncated or corrupt") from None
            count += 1
            seen[c.id] += 1
            try:
                msg = ts.deserialize_cdr(data, c.msgtype)
            except Exception as exc:
                raise ConfigError(f"{self.path}: topic {c.topic}: message at log time "
                                  f"{t * 1e-9:.9f} s cannot be decoded as {c.msgtype} "
                                  f"({_first_line(exc)})") from None
            yield c, t, msg

    def close(self) -> None:
        self.reader.close()


def _first_line(exc: Exception) -> str:
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0]}" if text else type(exc).__name__


def bag_config(bag: Path, params: NodeConfig | None, controller: str | None
               ) -> tuple[NodeConfig, str]:
    """The node configuration of a replay and a note on where it came from: ``params`` if
    given, else what a companion recording stored in the bag, else the defaults with the side
    read from the bag (:func:`companion.ros.infer.infer_side`); ``controller`` replaces its
    controller."""
    note = ""
    if params is None:
        reader = BagReader(bag)
        try:
            stored = reader.recorded_config()
            if stored:
                params = config_from_mapping(stored, f"{bag}: metadata {CUSTOM_KEY}: ")
            else:
                from companion.ros.infer import infer_side

                params = config_from_mapping({})
                side, mean = infer_side(reader, params)
                params = config_from_mapping({"formation": {"bearing": side}})
                note = (f"no companion parameters in the bag: the defaults, with the side "
                        f"read from the data ({side}: mean bearing {mean:.2f} rad) and the "
                        f"person topic's type; --params FILE.yaml gives others")
        finally:
            reader.close()
    if controller:
        params = config_from_mapping({**config_mapping(params), "controller": controller})
    return params, note


def _ticks(reader: BagReader, config: NodeConfig, inputs: list[Any]) -> list[int]:
    """The tick times (ns) of the recording (see the module docstring)."""
    t = config.ros.topics
    status = reader.topics.get(t.status)
    source = None
    if status is not None and status.msgtype == "diagnostic_msgs/msg/DiagnosticArray":
        source = status
    elif t.cmd_vel in reader.topics and \
            reader.topics[t.cmd_vel].msgtype == "geometry_msgs/msg/TwistStamped":
        source = reader.topics[t.cmd_vel]
    if source is not None:
        stamps = [convert.stamp_ns(m.header.stamp) for _, _, m in reader.messages([source])]
        if stamps:
            return sorted(set(stamps))
    times = [lt for _, lt, _ in reader.messages(inputs)]
    first, last = min(times), max(times)
    dt = int(round(config.params.dt * 1e9))
    return list(range(first, last + 1, dt))


def replay(bag: Path, config: NodeConfig, out_bag: Path,
           progress: Callable[[int, int], None] | None = None) -> dict[str, Any]:
    """Replay ``bag`` through the node of ``config`` into a new bag at ``out_bag``; returns
    the metrics (docs/recording.md). ``progress(done, total)`` counts the node's ticks."""
    reader = BagReader(bag)
    r = config.ros
    try:
        t = r.topics
        inputs = reader.connection(t.odom, ("nav_msgs/msg/Odometry",), "odometry")
        inputs += reader.connection(t.person, person_types(r.person_type),
                                    f"person detections, ros.person_type {r.person_type}")
        if t.scan:
            inputs += reader.connection(t.scan, ("sensor_msgs/msg/LaserScan",), "LiDAR scans")
        recorded = reader.topics.get(t.cmd_vel)
        if recorded is not None:
            reader.connection(t.cmd_vel, _TWISTS, "velocity commands")
        out = open_bag(out_bag, config)
        reader.typestore = out.typestore
        try:
            return _run(reader, config, inputs, recorded, out, progress)
        finally:
            out.close()
    finally:
        reader.close()


def _run(reader: BagReader, config: NodeConfig, inputs: list[Any], recorded: Any,
         out: BagWriter, progress: Callable[[int, int], None] | None) -> dict[str, Any]:
    r, p = config.ros, config.params
    for c in inputs:
        if c.msgcount == 0:
            raise ConfigError(f"{reader.path}: topic {c.topic}: no messages")
    ticks = _ticks(reader, config, inputs)
    ros = r.__class__(**{**r.__dict__, "use_sim_time": False})
    now = [ticks[0]]                         # ns: the log time the node sees things at
    bus = MemoryBus()
    node = RecordedNode(NodeConfig(p, ros, config.controller),
                        MemoryTransport(bus, out.typestore), out, log_clock=lambda: now[0],
                        clock=lambda: now[0] * 1e-9, time_base=TimeBase.at(ticks[0]))
    feed = MemoryTransport(bus, out.typestore)
    publishers = {c.id: feed.publisher(c.topic, c.msgtype) for c in inputs}
    rows: list[tuple[int, float, float, float, float, float]] = []
    recorded_cmds: list[tuple[int, float, float]] = []
    k = 0

    def tick_until(limit_ns: int | None) -> None:
        nonlocal k
        while k < len(ticks) and (limit_ns is None or ticks[k] < limit_ns):
            now[0] = ticks[k]
            cmd = node.tick(node.time.since(ticks[k]))
            v = node.view
            e = (math.nan,) * 3
            if v.estimate is not None and math.isfinite(v.robot.x):
                w = v.estimate.walker
                e = relative_state(v.robot.x, v.robot.y, v.robot.theta, w.x, w.y, w.theta,
                                   p.robot.d)
            rows.append((ticks[k], cmd.v, cmd.omega, *e))
            k += 1
            if progress is not None:
                progress(k, len(ticks))

    streams = inputs + ([recorded] if recorded is not None else [])
    for c, log_ns, msg in reader.records(streams):
        if recorded is not None and c.id == recorded.id:
            tick_until(log_ns + 1)  # the command a tick published is logged at or after it
            out.write(c.topic + RECORDED_SUFFIX, c.msgtype, log_ns, msg)
            recorded_cmds.append((log_ns, *convert.twist_velocity(msg)))
            continue
        tick_until(log_ns)          # an input logged at a tick's time came before the tick
        now[0] = log_ns
        publishers[c.id](msg)
    tick_until(None)
    node.close()
    return _metrics(rows, recorded_cmds, config)


def _metrics(rows: list[tuple], recorded: list[tuple[int, float, float]],
             config: NodeConfig) -> dict[str, Any]:
    times = [row[0] for row in rows]
    a = np.array([row[1:] for row in rows], dtype=float).reshape(-1, 5)
    f = config.params.formation
    seen = np.isfinite(a[:, 2])
    n = int(seen.sum())
    log = Log({"rho": a[seen, 2], "rho_d": np.full(n, f.distance), "alpha": a[seen, 3],
               "alpha_d": np.full(n, f.bearing), "beta": a[seen, 4],
               "beta_ref": np.zeros(n)})
    e = metrics.errors(log)
    out: dict[str, Any] = {"controller": config.controller, "ticks": len(rows),
                           "ticks_with_estimate": n}
    for key, unit in (("rho", "m"), ("alpha", "rad"), ("beta", "rad")):
        out[f"rmse_{key}_{unit}"] = float(np.sqrt(np.mean(e[key] ** 2))) if n else None
    # The recorded command of a tick: the first /cmd_vel logged at or after it, before the
    # next tick.
    pairs = []
    j = 0
    for i, t in enumerate(times):
        while j < len(recorded) and recorded[j][0] < t:
            j += 1
        end = times[i + 1] if i + 1 < len(times) else None
        if j < len(recorded) and (end is None or recorded[j][0] < end):
            pairs.append((a[i, 0] - recorded[j][1], a[i, 1] - recorded[j][2]))
    d = np.array(pairs, dtype=float).reshape(-1, 2)
    out["recorded_commands"] = len(recorded)
    out["paired_commands"] = len(pairs)
    for i, name in enumerate(("v_mps", "omega_radps")):
        out[f"cmd_diff_{name}_rms"] = float(np.sqrt(np.mean(d[:, i] ** 2))) if len(d) else None
        out[f"cmd_diff_{name}_max"] = float(np.max(np.abs(d[:, i]))) if len(d) else None
    return out
