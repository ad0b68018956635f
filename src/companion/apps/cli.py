"""Command-line interface: ``companion COMMAND`` (the commands are in :mod:`companion.apps.
commands`, :mod:`~companion.apps.evaluation` and :mod:`~companion.apps.rosapps`).

Bad usage or bad input files exit with code 2 and one line on stderr naming the file, line or
key. Outputs are written whole or not at all; a reader that goes away (``| head``) is quiet.
"""

from __future__ import annotations

import argparse
import importlib
import os
import re
import signal
import sys
import threading
from collections.abc import Sequence
from importlib.metadata import version

from companion.apps.flags import dask_flag as _dask
from companion.apps.flags import help_range as rng
from companion.apps.flags import plant_flag as _plant
from companion.apps.flags import sensing_flags as _sensing
from companion.apps.flags import workers_flag as _workers
from companion.config import hint
from companion.errors import CompanionError

# Choices spelled out so that --help and usage errors need no numpy, numba or scipy (they
# answer in well under 0.2 s); tests/test_cli.py checks them against the registries
# (companion.control.CONTROLLERS, companion.evaluate.tuning.SPACES, companion.params.SIDES).
CONTROLLERS = ("ic", "lqr", "lqr-paper", "lqr-tuned", "pid", "vsm")
TUNABLE = ("ic", "lqr", "pid", "vsm")
SIDES = ("behind", "front", "left", "right")


class OneLineParser(argparse.ArgumentParser):
    """argparse, but usage errors are one line on stderr (exit code 2) naming the command."""

    def error(self, message: str) -> None:  # type: ignore[override]
        command = self.prog.removeprefix("companion").strip()
        where = f"{command}: " if command else ""
        self.exit(2, f"companion: error: {where}{message}{suggestion(self, message)} "
                     "(see --help)\n")


def suggestion(parser: argparse.ArgumentParser, message: str) -> str:
    """The "; did you mean" suffix for argparse's ``message``: the closest choice to an
    invalid one, or flag (of ``parser`` and its commands) to an unrecognized one."""
    choice = re.search(r"invalid choice: '(.*?)' \(choose from (.*)\)$", message)
    if choice:
        return hint(choice[1], re.findall(r"'([^']*)'", choice[2]))
    unknown = re.search(r"unrecognized arguments: (.*)$", message)
    if unknown:
        flags = [f for f in unknown[1].split() if f.startswith("--")]
        return hint(flags[0].partition("=")[0], _flags(parser)) if flags else ""
    return ""


def _flags(parser: argparse.ArgumentParser) -> list[str]:
    """Every option string of ``parser`` and of its sub-commands."""
    flags = []
    for action in parser._actions:
        flags += [f for f in action.option_strings if f.startswith("--")]
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                flags += _flags(sub)
    return flags


def parser() -> argparse.ArgumentParser:
    ap = OneLineParser(prog="companion",
                       description="Side-by-side companion robot control (LQR).")
    ap.add_argument("--version", action="version", version=f"companion {version('companion')}")
    sub = ap.add_subparsers(dest="command", required=True, parser_class=OneLineParser)

    run = sub.add_parser("run", help="simulate one scenario and write log.csv, metrics.json")
    run.add_argument("scenario", help="built-in scenario name (see 'companion scenarios') "
                                      "or a TOML file")
    run.add_argument("--controller", choices=CONTROLLERS,
                     help="controller (default: the scenario's)")
    run.add_argument("--side", choices=SIDES, help="side of the person to walk on")
    run.add_argument("--bearing", metavar="RAD", help="desired bearing alpha_d in rad "
                     f"(left pi/2, behind pi, right 3pi/2), {rng('--bearing', 'RAD')}")
    run.add_argument("--distance", metavar="M", help="desired distance rho_d, "
                     f"{rng('--distance', 'M')}, with the slot outside "
                     "keepout.person_clearance")
    run.add_argument("--start", metavar="X,Y,THETA", help="robot start pose (m, m, rad), "
                     f"each {rng('--start', 'X')}; default: in the slot. Write "
                     "--start=-1,2,0 when X is negative")
    run.add_argument("--person-csv", metavar="FILE", help="CSV with header t,x,y replacing "
                     "the scenario's person motion (duration: the recording's)")
    run.add_argument("--duration", metavar="S", help=f"simulated time, {rng('--duration', 'S')} "
                     "and at least dt")
    run.add_argument("--params", metavar="FILE", help="TOML file of parameter overrides "
                     "(docs/parameters.md)")
    run.add_argument("--obstacles", choices=("truth", "lidar"),
                     help="the controller knows the obstacles exactly (truth) or sees what "
                          "the simulated LiDAR detects (lidar); default: the scenario's")
    run.add_argument("--out", metavar="DIR", help="output folder (default out/SCENARIO)")
    run.add_argument("--plot", action="store_true", help="also write trajectory.png, "
                     "errors.png, inputs.png (and avoidance.png when there are obstacles)")
    run.add_argument("--bag", metavar="DIR", help="also record the run as a ROS 2 bag (MCAP) "
                     "with a Foxglove scene, through the ROS 2 node (docs/recording.md)")
    run.add_argument("--animate", metavar="FILE", help="also draw the run as an animation: "
                     "FILE.gif, or FILE.mp4 where ffmpeg is on PATH (docs/animations.md)")
    run.add_argument("--seed", type=int, metavar="N", help="seed of the sensing noise, "
                     f"{rng('--seed', 'N')} (default: the scenario's, 0 unless it sets one)")
    _sensing(run)
    run.set_defaults(func="cmd_run")

    rp = sub.add_parser("reproduce", help="the paper's Fig. 3, Table 2, Fig. 4, Fig. 7 and Table 3 "
                        "(its real-robot runs simulated with an EM-tracker-like and a "
                        "leg-tracker-like sensor)")
    rp.add_argument("--out", metavar="DIR", help="output folder (default out/reproduce); a "
                    "killed run keeps the tables' episodes there for the next call")
    _dask(rp)
    _workers(rp)
    rp.set_defaults(func="cmd_reproduce")

    ev = sub.add_parser("evaluate", help="run an evaluation suite (every combination of person "
                        "motions, sides, sensing, controllers and seeds) and summarise it with "
                        "intervals and paired comparisons (docs/evaluation.md)")
    ev.add_argument("suite", help="suite TOML file (see suites/)")
    ev.add_argument("--out", metavar="DIR", help="output folder (default out/evaluate-NAME); "
                    "a killed run continues there on the next call")
    _dask(ev)
    _workers(ev)
    ev.set_defaults(func="evaluation.cmd_evaluate")

    tn = sub.add_parser("tune", help="tune a controller's parameters with Optuna on a suite "
                        "(docs/baselines.md, docs/evaluation.md)")
    tn.add_argument("controller", choices=TUNABLE)
    tn.add_argument("--suite", default="tune-tracks", metavar="SUITE",
                    help="evaluation suite (a shipped name or a TOML file) whose episodes of "
                    "the controller score a trial (default tune-tracks: the procedure every "
                    "controller is tuned with, docs/baselines.md)")
    tn.add_argument("--trials", type=int, default=30, metavar="N", help="trials in the study, "
                    f"the budget, {rng('--trials', 'N')} (default 30)")
    tn.add_argument("--seed", type=int, default=0, metavar="N",
                    help=f"the sampler's seed, {rng('--seed', 'N')} (default 0)")
    tn.add_argument("--storage", metavar="URL", help="Optuna storage that keeps the trials, "
                    "e.g. sqlite:///study.db; a stopped study resumes from it")
    _dask(tn)
    tn.add_argument("--out", metavar="DIR", help="output folder for best.toml and trials.csv "
                    "(default out/tune-CONTROLLER)")
    _workers(tn)
    tn.set_defaults(func="evaluation.cmd_tune")

    sc = sub.add_parser("scenarios", help="list the built-in scenarios")
    sc.set_defaults(func="cmd_scenarios")

    cv = sub.add_parser("convergence", help="Fig. 3: 48 starts, settling and safety table")
    cv.add_argument("--controller", default="lqr", choices=CONTROLLERS)
    cv.add_argument("--speeds", default="0.5,1.0", metavar="V1,V2",
                    help=f"person speeds, each {rng('--speeds', 'V')} (default 0.5,1.0)")
    cv.add_argument("--duration", default="30", metavar="S",
                    help=f"simulated time per run, {rng('--duration', 'S')} (default 30)")
    cv.add_argument("--settle-limit", metavar="S",
                    help=f"a run must settle within this time, {rng('--settle-limit', 'S')} "
                         "(default: the convergence suite's, 20)")
    cv.add_argument("--params", metavar="FILE", help="TOML file of parameter overrides")
    cv.add_argument("--out", metavar="DIR", help="output folder (default out/convergence); "
                    "a killed run continues there on the next call (not with --plot)")
    cv.add_argument("--plot", action="store_true", help="write the Fig. 3 panels as PNG")
    _dask(cv)
    _workers(cv)
    _sensing(cv)
    cv.set_defaults(func="suites.cmd_convergence")

    pd = sub.add_parser("pedestrians", help="every controller beside real walkers (ETH/UCY), ideal "
                        "or realistic sensing (docs/sensing.md)")
    pd.add_argument("--data", metavar="DIR", help="folder of the ETH/UCY files (default: "
                    "the copy shipped with companion, or $COMPANION_PEDESTRIANS)")
    pd.add_argument("--controller", default="lqr", choices=[*CONTROLLERS, "all"],
                    help="a controller, or all of them on the same runs (default lqr)")
    pd.add_argument("--side", default="both", choices=[*SIDES, "both"],
                    help="side of the person (default: both, one run each)")
    pd.add_argument("--min-speed", default="0.6", metavar="MPS",
                    help=f"only tracks with a higher mean speed, {rng('--min-speed', 'MPS')} "
                         "(default 0.6)")
    pd.add_argument("--min-duration", default="15", metavar="S",
                    help=f"only tracks at least this long, {rng('--min-duration', 'S')} "
                         "(default 15)")
    pd.add_argument("--params", metavar="FILE", help="TOML file of parameter overrides")
    pd.add_argument("--out", metavar="DIR", help="output folder (default out/pedestrians); "
                    "a killed run continues there on the next call")
    _dask(pd)
    _workers(pd)
    _sensing(pd)
    pd.set_defaults(func="suites.cmd_pedestrians")

    sk = sub.add_parser("soak", help="long run of a random walker among obstacles "
                        "(docs/safety.md); exit 1 on a collision or a non-finite value")
    sk.add_argument("--duration", default="3600", metavar="S",
                    help=f"simulated time, {rng('--duration', 'S')} (default 3600)")
    sk.add_argument("--seed", type=int, default=0, metavar="N",
                    help=f"world and walk seed, {rng('--seed', 'N')} (default 0)")
    sk.add_argument("--controller", default="lqr", choices=CONTROLLERS)
    sk.add_argument("--params", metavar="FILE", help="TOML file of parameter overrides")
    sk.add_argument("--log", action="store_true", help="also write log.csv")
    sk.add_argument("--out", metavar="DIR", help="output folder (default out/soak)")
    _sensing(sk)
    sk.set_defaults(func="cmd_soak")

    fz = sub.add_parser("fuzz", help="random closed-loop episodes (walkers up to 2 m/s among "
                        "pillars, any formation, random starts, every controller, ideal and "
                        "realistic sensing; docs/safety.md); exit 1 on a collision or a "
                        "robot-caused protective violation")
    fz.add_argument("--steps", type=int, default=1_000_000, metavar="N",
                    help="run episodes until at least N steps in all, "
                         f"{rng('--steps', 'N')} (default 1,000,000)")
    fz.add_argument("--seed", type=int, default=0, metavar="N",
                    help=f"seed, {rng('--seed', 'N')}; episode i has seed N * 10,000,000 + i "
                         "(default 0)")
    fz.add_argument("--controllers", metavar="A,B", help=f"controllers (default all: "
                    f"{','.join(CONTROLLERS)})")
    fz.add_argument("--sensing", metavar="A,B", help="sensing profiles: ideal, realistic, "
                    "em-tracker or TOML files of sensing keys (docs/sensing.md), separated by "
                    "commas (default: ideal,realistic)")
    fz.add_argument("--replay", type=int, metavar="SEED", help="run the episode of this seed "
                    f"({rng('--replay', 'SEED')}; a row of fuzz.csv) with one --controllers and "
                    "one --sensing, and write its log.csv and episode.json")
    fz.add_argument("--params", metavar="FILE", help="TOML file of parameter overrides (the "
                    "episodes draw their own formation and take --sensing's profiles)")
    fz.add_argument("--out", metavar="DIR", help="output folder (default out/fuzz); a killed "
                    "run continues there on the next call")
    _plant(fz)
    _dask(fz)
    _workers(fz)
    fz.set_defaults(func="cmd_fuzz")

    bn = sub.add_parser("bench", help="step latency per controller alone and in the full "
                        "stack, full-stack throughput, first-step time and memory "
                        "(docs/performance.md)")
    bn.add_argument("--json", action="store_true", help="print the figures as JSON")
    bn.add_argument("--episodes", type=int, default=48, metavar="N",
                    help=f"figure-8 episodes in the throughput measurement, "
                         f"{rng('--episodes', 'N')} (default 48)")
    bn.add_argument("--duration", default="60", metavar="S",
                    help=f"simulated time per episode, {rng('--duration', 'S')} (default 60)")
    bn.add_argument("--no-first-step", action="store_true",
                    help="skip the fresh-process first-step measurement (numba compile)")
    bn.add_argument("--out", metavar="FILE", help="also write the JSON figures to FILE")
    _workers(bn)
    bn.set_defaults(func="cmd_bench")
    _ros_commands(sub)
    return ap


def _transport(p: argparse.ArgumentParser) -> None:
    p.add_argument("--transport", choices=("dds", "zenoh", "rclpy"),
                   help="ROS 2 wire protocol: dds or zenoh spoken by companion, or rclpy (the "
                        "installed ROS 2; needed for ros2 param on a Fast DDS graph) "
                        "(default: the parameters' ros.transport, dds)")
    p.add_argument("--zenoh-connect", metavar="ENDPOINT",
                   help="Zenoh router to connect to (default tcp/127.0.0.1:7447)")
    p.add_argument("--domain-id", type=int, metavar="N",
                   help=f"ROS domain, {rng('--domain-id', 'N')} (default: the parameters' "
                        f"ros.domain_id, else $ROS_DOMAIN_ID, else 0)")


def _ros_commands(sub) -> None:
    nd = sub.add_parser("node", help="the controller as a ROS 2 node: /odom, /scan, /person in, "
                        "/cmd_vel out (docs/ros2.md)")
    nd.add_argument("--params", metavar="FILE", help="ROS 2 parameters YAML "
                    "(companion: ros__parameters: ...)")
    nd.add_argument("--scenario", metavar="NAME", help="take the controller and the "
                    "companion parameters (formation, weights, limits) of this scenario, as "
                    "`companion sim-robot NAME` runs it, instead of those of --params (whose "
                    "ros section still applies)")
    nd.add_argument("--controller", choices=CONTROLLERS,
                    help="controller (default: the parameters', lqr)")
    nd.add_argument("--duration", metavar="S", help="stop after S s of the node's time, "
                    f"{rng('--duration', 'S')} (default: run until SIGINT or SIGTERM)")
    nd.add_argument("--bag", metavar="DIR", help="record what the node receives and sends, "
                    "and a Foxglove scene, as a ROS 2 bag (MCAP) (docs/recording.md)")
    nd.add_argument("--use-sim-time", action="store_true", help="take time from /clock, as "
                    "`companion sim-robot --lockstep` or --rate publishes it (ros.use_sim_time)")
    nd.add_argument("--sensing", metavar="PROFILE", help="ideal, realistic, em-tracker or a "
                    "TOML file of sensing keys: the base's actuator lag the node allows for, as "
                    "sim-robot --sensing (docs/sensing.md); default: the parameters'")
    _transport(nd)
    nd.set_defaults(func="rosapps.cmd_node")

    sr = sub.add_parser("sim-robot", help="the simulator as a ROS 2 robot: /odom, /scan, "
                        "/person, /tf, /clock out, /cmd_vel in (docs/ros2.md)")
    sr.add_argument("scenario", help="built-in scenario name or a TOML file")
    sr.add_argument("--ros-params", metavar="FILE", help="ROS 2 parameters YAML (its ros "
                    "section: topics, frames, transport)")
    sr.add_argument("--person-type", choices=("point", "pose", "pose_array", "odometry"),
                    help="message type of the person detections (default: the parameters' "
                         "ros.person_type; auto: what the sensing measures, odometry with a "
                         "speed, pose with a heading, else point)")
    sr.add_argument("--rate", metavar="X", help=f"real-time factor, {rng('--rate', 'X')}; "
                    "other than 1 publishes /clock (use_sim_time) (default 1)")
    sr.add_argument("--lockstep", action="store_true", help="lock step with the node: "
                    "publish /clock and move on only once the node answered each period's "
                    "/clock (at most 2 s); start the node with --use-sim-time")
    sr.add_argument("--wait", default="10", metavar="S", help="wait up to S s for the node's "
                    f"first command before starting, {rng('--wait', 'S')} (default 10)")
    sr.add_argument("--duration", metavar="S", help=f"simulated time, {rng('--duration', 'S')}")
    sr.add_argument("--seed", type=int, metavar="N",
                    help=f"sensing noise seed, {rng('--seed', 'N')}")
    sr.add_argument("--out", metavar="DIR", help="output folder (default "
                    "out/sim-robot-SCENARIO)")
    sr.add_argument("--bag", metavar="DIR", help="record what the robot sends and receives, "
                    "and a Foxglove scene, as a ROS 2 bag (MCAP) (docs/recording.md)")
    _sensing(sr)
    _transport(sr)
    sr.set_defaults(func="rosapps.cmd_sim_robot", controller=None, side=None, bearing=None,
                    distance=None, start=None, person_csv=None, params=None, obstacles=None)

    rb = sub.add_parser("replay", help="replay a ROS 2 bag's odometry, scan and person "
                        "detections through the node, open loop (docs/recording.md)")
    rb.add_argument("bag", help="rosbag2 folder (sqlite3 or MCAP storage)")
    rb.add_argument("--controller", choices=CONTROLLERS,
                    help="controller (default: the recording's, else lqr)")
    rb.add_argument("--params", metavar="FILE", help="ROS 2 parameters YAML (default: those a "
                    "companion recording stored in the bag, else the defaults with the side "
                    "read from the bag)")
    rb.add_argument("--topics", nargs="+", metavar="KEY=NAME",
                    help="topic names, e.g. odom=/robot/odom person=/people scan= (none)")
    rb.add_argument("--out", metavar="DIR", help="output folder (default out/replay-BAG)")
    rb.set_defaults(func="rosapps.cmd_replay")


class Terminated(BaseException):
    """SIGTERM: unwinds like Ctrl-C, so no output is half written."""


def _terminate(signum, frame) -> None:
    raise Terminated


def empty_value(args: argparse.Namespace) -> str | None:
    """The flag (or argument) given an empty text, which would otherwise read as not given:
    ``--out ""`` must not write to the default folder."""
    for key, value in vars(args).items():
        if isinstance(value, str) and not value.strip():
            return key if key in ("scenario", "bag") else "--" + key.replace("_", "-")
    return None


def main(argv: Sequence[str] | None = None) -> int:
    ap = parser()
    args = ap.parse_args(argv)
    empty = empty_value(args)
    if empty:
        print(f"companion: error: {empty}: expected a value, got an empty text", file=sys.stderr)
        return 2
    main_thread = threading.current_thread() is threading.main_thread()
    before = signal.signal(signal.SIGTERM, _terminate) if main_thread else None
    try:
        from threadpoolctl import threadpool_limits

        from companion import _jit
        from companion.apps import commands
        from companion.apps.progress import compile_kernels

        if args.command != "scenarios" and _jit.cold():
            compile_kernels(main_thread)
        # The controller's matrices are 5x5: BLAS threads only cost hand-over time.
        with threadpool_limits(limits=1):
            if "." in args.func:    # a command of another module: "module.function"
                module, _, name = args.func.partition(".")
                commands = importlib.import_module(f"companion.apps.{module}")
                return getattr(commands, name)(args)
            return getattr(commands, args.func)(args)
    except CompanionError as exc:
        print(f"companion: error: {exc}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, Terminated) as exc:
        ctrl_c = isinstance(exc, KeyboardInterrupt)
        print(f"companion: {'interrupted' if ctrl_c else 'terminated'}; no output was changed",
              file=sys.stderr)
        return 130 if ctrl_c else 143
    except BrokenPipeError:
        # The reader went away (``companion run ... | head``): stop quietly, and keep Python
        # from failing again when it flushes stdout at exit.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    finally:
        if main_thread:
            signal.signal(signal.SIGTERM, before)


if __name__ == "__main__":
    sys.exit(main())
