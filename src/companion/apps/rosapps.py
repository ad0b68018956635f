"""``companion node``, ``companion sim-robot`` and ``companion replay``: the ROS 2 commands
(docs/ros2.md, docs/recording.md); ``--bag`` of these and of ``companion run``."""

from __future__ import annotations

import argparse
import dataclasses
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from companion import _jit
from companion.apps.args import (
    UsageError,
    build_scenario,
    duration_arg,
    number_arg,
    output_dir,
    with_sensing,
    wrote,
)
from companion.apps.bags import bag_arg, bag_outputs
from companion.apps.progress import sized_bar
from companion.io import Outputs, write_json


def _ros_overrides(ros, args: argparse.Namespace):
    changes = {}
    if args.transport:
        changes["transport"] = args.transport
    if args.zenoh_connect:
        from companion.ros.settings import endpoint_problem

        problem = endpoint_problem(args.zenoh_connect)
        if problem:
            raise UsageError(f"--zenoh-connect: expected {problem}, got {args.zenoh_connect!r}")
        changes["zenoh_connect"] = args.zenoh_connect
    if args.domain_id is not None:
        changes["domain_id"] = int(number_arg(str(args.domain_id), "--domain-id", "N"))
    if getattr(args, "use_sim_time", False):
        changes["use_sim_time"] = True
    return dataclasses.replace(ros, **changes)


#: How long ``sim-robot --lockstep`` waits each period for the node's command (wall time).
LOCKSTEP_WAIT_S = 2.0
#: sim-robot says how far it is every this many seconds of wall time.
PROGRESS_S = 5.0


def progress_lines(duration: float) -> Callable[[float], None]:
    """A sample callback that prints ``t of duration s`` at most every :data:`PROGRESS_S` s
    of wall time (a run in lock step with a slow or silent node can take long)."""
    last = time.monotonic()

    def sample(t: float) -> None:
        nonlocal last
        if time.monotonic() - last >= PROGRESS_S:
            last = time.monotonic()
            print(f"companion sim-robot: {t:.1f} of {duration:g} s", flush=True)
    return sample


class Stop(threading.Event):
    """Set by SIGINT or SIGTERM; ``code`` is the exit code the signal asks for."""

    code = 0


@contextmanager
def stop_on_signals() -> Iterator[Stop]:
    """A :class:`Stop` set by SIGINT or SIGTERM (instead of their usual exceptions) inside."""
    stop = Stop()

    def handler(signum, frame) -> None:
        stop.code = 128 + signum
        stop.set()

    before = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield stop
    finally:
        for s, old in before.items():
            signal.signal(s, old)


def cmd_node(args: argparse.Namespace) -> int:
    from companion.ros.settings import load_node_config

    config = load_node_config(args.params)
    config = dataclasses.replace(config, ros=_ros_overrides(config.ros, args))
    if args.scenario:                  # the parameters of the world sim-robot runs
        from companion.sim.scenario import load_scenario

        sc = load_scenario(args.scenario)
        config = dataclasses.replace(config, params=sc.params, controller=sc.controller)
    config = dataclasses.replace(config, params=with_sensing(config.params, args))
    if args.controller:
        config = dataclasses.replace(config, controller=args.controller)
    limit = duration_arg(args.duration) if args.duration else None
    bag = bag_arg(args.bag)
    source = "--domain-id" if args.domain_id is not None else \
        f"ros.domain_id in {args.params}" if config.ros.domain_id is not None else ""
    with bag_outputs(bag) as staged:
        code = _node(config, staged, limit, source)
    if bag is not None:
        print(wrote([bag]), flush=True)
    return code


def _node(config, staged: Path | None, limit: float | None, domain_source: str) -> int:
    from companion.ros.wire import domain_of, open_transport

    transport = open_transport(config.ros)   # first: discovery goes on while the node starts
    bag = node = None
    try:
        from companion.ros.node import CompanionNode
        from companion.ros.record import RecordedNode, open_bag
        from companion.ros.spin import spin

        _jit.warm_up()             # compile or load the kernels before the first period
        bag = open_bag(staged, config) if staged is not None else None
        node = CompanionNode(config, transport) if bag is None \
            else RecordedNode(config, transport, bag)
        terminal = _terminal(node.log)
        r = config.ros
        domain, source = domain_of(r)
        node.log.info(f"{config.controller} at {1 / config.params.dt:g} Hz over {r.transport} "
                      f"(domain {domain} from {domain_source or source}); {r.topics.odom}, "
                      f"{r.topics.scan or 'no scan'}, {r.topics.person} in, {r.topics.cmd_vel} "
                      f"out; parameters at {node.name}/get_parameters ...")
        with stop_on_signals() as stop:
            ticks = spin(node, stop, limit)
        meter = node.stack.delays
        measured = ", ".join(f"{name} {value:.3f} s" for name, value in (
            ("detection latency", meter.latency), ("actuator lag", meter.tau))
            if value is not None) or "nothing yet"
        node.log.info(f"stopped after {ticks} periods; sent a zero velocity; measured "
                      f"delays: {measured}")
        node.log.removeHandler(terminal)
    finally:
        if node is not None:
            node.close()
        transport.close()
        if bag is not None:
            bag.close()
    return 0


def _terminal(log):
    """The node's log on the terminal: ``companion node: ...`` on stdout, warnings and worse
    on stderr."""
    import logging
    import sys

    class Split(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            warn = record.levelno >= logging.WARNING
            print(f"companion node: {'warning: ' * warn}{record.getMessage()}",
                  file=sys.stderr if warn else sys.stdout, flush=True)

    handler = Split(logging.INFO)
    log.addHandler(handler)
    log.setLevel(logging.INFO)
    return handler


def cmd_sim_robot(args: argparse.Namespace) -> int:
    from companion.apps.commands import _write_run, summary_lines
    from companion.ros.record import recording_sim_robot
    from companion.ros.settings import load_node_config
    from companion.ros.sim_robot import SIM_EPOCH_NS, Interrupted, Pacer, run_sim_robot
    from companion.ros.wire import domain_of, open_transport

    sc = build_scenario(args)
    ros = _ros_overrides(load_node_config(args.ros_params).ros, args)
    if args.person_type:
        ros = dataclasses.replace(ros, person_type=args.person_type)
    rate = number_arg(args.rate, "--rate", "X") if args.rate else 1.0
    if (rate != 1.0 or args.lockstep) and not ros.use_sim_time:
        ros = dataclasses.replace(ros, use_sim_time=True)   # other rates need /clock
    lockstep = LOCKSTEP_WAIT_S if args.lockstep else 0.0
    wait = number_arg(args.wait, "--wait", "S")
    out = output_dir(Path(args.out or Path("out") / f"sim-robot-{sc.name}"))
    bag = bag_arg(args.bag)
    _jit.warm_up()                     # compile or load the kernels before the first period
    transport = open_transport(ros, "companion_sim_robot", robot=True)
    try:
        with stop_on_signals() as stop:
            pacer = Pacer(rate, stop)
            # simulated time on the wire: the epoch one period before the first sample (so
            # the node can tick on /clock while waiting); else the system clock at t = 0
            epoch = SIM_EPOCH_NS + int(round(sc.params.dt * 1e9)) if ros.use_sim_time else None
            domain, source = domain_of(ros)
            source = "--domain-id" if args.domain_id is not None else source
            print(f"companion sim-robot: {sc.name}, {sc.duration:g} s at {rate:g}x real time "
                  f"over {ros.transport} (domain {domain} from {source}); waiting for a node "
                  f"on {ros.topics.cmd_vel}", flush=True)
            try:
                with bag_outputs(bag) as staged:
                    if staged is None:
                        log, robot = run_sim_robot(sc.episode(), transport, ros, pacer,
                                                   epoch, progress_lines(sc.duration),
                                                   wait_s=wait, lockstep_s=lockstep)
                    else:
                        log, robot = recording_sim_robot(sc.episode(), transport, ros, pacer,
                                                         epoch, staged, wait_s=wait,
                                                         lockstep_s=lockstep,
                                                         after=progress_lines(sc.duration))
            except Interrupted:
                print("companion sim-robot: interrupted; nothing written", flush=True)
                return stop.code or 130
    finally:
        transport.close()
    if robot.started is False:
        status, reason = robot.report.status, robot.report.reason
        print(f"companion sim-robot: the node kept the robot stopped for the whole run (its "
              f"last status: {status}: {reason}); nothing written. With --lockstep or --rate "
              f"the node must take /clock: companion node --use-sim-time", file=sys.stderr)
        return 1
    with Outputs(out, "sim-robot") as stage:
        m, written = _write_run(stage, sc, False, [log], {"controller": "(over ROS 2)",
                                                          "commands_received": robot.commands})
    print(f"companion sim-robot: {robot.commands} commands received in {len(log)} periods")
    print("\n".join(summary_lines(m)))
    print(wrote([*(out / name for name in written), *([bag] if bag is not None else [])]))
    return 0 if robot.commands else 1


def topics_arg(config, pairs: list[str] | None):
    """``config`` with the topics of ``--topics KEY=NAME ...`` (KEY a field of ros.topics)."""
    from companion.ros.parameters import config_mapping
    from companion.ros.settings import Topics, config_from_mapping

    if not pairs:
        return config
    keys = [f.name for f in dataclasses.fields(Topics)]
    mapping = config_mapping(config)
    for pair in pairs:
        key, eq, name = pair.partition("=")
        if not eq or key not in keys:
            raise UsageError(f"--topics: expected KEY=NAME with KEY one of {', '.join(keys)}, "
                             f"got {pair!r}")
        mapping["ros"]["topics"][key] = name
    return config_from_mapping(mapping, "--topics: ")


def cmd_replay(args: argparse.Namespace) -> int:
    from companion.ros.replay import bag_config, replay
    from companion.ros.settings import load_node_config

    bag = Path(args.bag)
    config, note = bag_config(bag, load_node_config(args.params) if args.params else None,
                              args.controller)
    if note:
        print(f"replay: {note}", flush=True)
    config = topics_arg(config, args.topics)
    out = output_dir(Path(args.out or Path("out") / f"replay-{bag.name}"))
    with Outputs(out, "replay") as stage, sized_bar("tick", "replaying") as progress:
        m = replay(bag, config, stage / "bag", progress)
        m["bag"] = str(bag)
        write_json(stage / "metrics.json", m)

    def num(x, scale=1.0):
        return "n/a" if x is None else f"{x * scale:.4g}"
    print(f"replayed {bag} through {config.controller}: {m['ticks']} ticks, "
          f"{m['ticks_with_estimate']} with a person estimate")
    print(f"  RMSE rho {num(m['rmse_rho_m'])} m, alpha {num(m['rmse_alpha_rad'])} rad, "
          f"beta {num(m['rmse_beta_rad'])} rad (robot pose from the recorded odometry, person "
          f"from the replayed tracker)")
    if m["paired_commands"]:
        print(f"  computed - recorded command over {m['paired_commands']} ticks: v RMS "
              f"{num(m['cmd_diff_v_mps_rms'])} m/s (max {num(m['cmd_diff_v_mps_max'])}), "
              f"omega RMS {num(m['cmd_diff_omega_radps_rms'])} rad/s "
              f"(max {num(m['cmd_diff_omega_radps_max'])})")
    print(wrote([out / "bag", out / "metrics.json"]))
    return 0
