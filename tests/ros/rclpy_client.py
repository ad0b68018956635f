"""A ROS 2 user's tools in rclpy (Jazzy, rmw_fastrtps_cpp) for the node tests, run as a bounded
subprocess: ``python rclpy_client.py PLAN.json``. It imports nothing of companion.

It publishes what the plan says, listens to the node's outputs, and (once the node's /cmd_vel
has been heard, if it listens to it) runs the plan's parameter calls through rclpy's
AsyncParameterClient (what ``ros2 param`` uses) against ``/companion``. The plan (JSON):
  publish:  [[topic, type, reliable, cdr_hex, rate_hz, stamp], ...]  (stamp: set header.stamp
            to the system clock before each publish)
  listen:   [[topic, type, reliable, transient_local], ...]
  params:   [["list"], ["get", [names]], ["set", [[name, value], ...]], ["describe", [names]],
             ["wait", seconds]]
  after:    seconds to go on publishing and listening after the calls
  call_timeout: seconds to wait for each call's answer (default 5)
  timeout:  seconds, the whole run
It prints one JSON line: the time it was up (after its node was created), when it first heard
each topic, what it heard (status key-values, log lines, commands, parameter events), the
parameter calls' results (or "timeout"), and errors.
"""

import importlib
import json
import sys
import time

import rclpy
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message


def get_message(msgtype):
    package, kind, name = msgtype.split("/")
    return getattr(importlib.import_module(f"{package}.{kind}"), name)


def qos(reliable, transient_local=False, depth=10):
    return QoSProfile(depth=depth, reliability=ReliabilityPolicy.RELIABLE if reliable
                      else ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if transient_local
                      else DurabilityPolicy.VOLATILE)


def value_of(pv):
    """The Python value of a rcl_interfaces/ParameterValue (None: not set)."""
    fields = {1: "bool_value", 2: "integer_value", 3: "double_value", 4: "string_value",
              6: "bool_array_value", 7: "integer_array_value", 8: "double_array_value",
              9: "string_array_value"}
    if pv.type not in fields:
        return None
    v = getattr(pv, fields[pv.type])
    return [x.item() if hasattr(x, "item") else x for x in v] if pv.type >= 6 else v


def main():
    with open(sys.argv[1]) as f:
        plan = json.load(f)
    start = time.time()
    rclpy.init()
    node = rclpy.create_node("rclpy_client")
    up = time.time()
    report = {"up": up, "first": {}, "status": [], "log": [], "cmd": [], "events": [],
              "calls": [], "errors": []}
    pubs = []
    for topic, msgtype, reliable, data, rate, stamped in plan["publish"]:
        cls = get_message(msgtype)
        pubs.append([node.create_publisher(cls, topic, qos(reliable)),
                     deserialize_message(bytes.fromhex(data), cls), 1.0 / rate, 0.0, stamped])

    def on(topic):
        def heard(msg):
            now = time.time()
            report["first"].setdefault(topic, now)
            if topic.endswith("status"):
                s = msg.status[0]
                report["status"].append({"level": int.from_bytes(s.level, "little")
                                         if isinstance(s.level, bytes) else int(s.level),
                                         "message": s.message,
                                         **{kv.key: kv.value for kv in s.values}})
            elif topic == "/rosout":
                report["log"].append([msg.name, int(msg.level), msg.msg])
            elif topic == "/parameter_events":
                report["events"].append([msg.node, [p.name for p in msg.new_parameters],
                                         [[p.name, value_of(p.value)]
                                          for p in msg.changed_parameters]])
            else:
                report["cmd"].append([now, msg.linear.x, msg.angular.z])
        return heard

    listened = {topic for topic, *_ in plan["listen"]}
    for topic, msgtype, reliable, transient_local in plan["listen"]:
        node.create_subscription(get_message(msgtype), topic, on(topic),
                                 qos(reliable, transient_local, 1000))
    deadline = start + plan["timeout"]
    calls = list(plan.get("params", []))
    client = AsyncParameterClient(node, "/companion") if calls else None
    stop_at = None

    def spin_for(seconds):
        end = time.time() + seconds
        while time.time() < min(end, deadline):
            now = time.time()
            for p in pubs:
                if now >= p[3]:
                    p[3] = now + p[2]
                    if p[4]:
                        p[1].header.stamp = node.get_clock().now().to_msg()
                    p[0].publish(p[1])
            rclpy.spin_once(node, timeout_sec=0.01)

    def wait(future):
        end = time.time() + plan.get("call_timeout", 5.0)
        while not future.done() and time.time() < end:
            spin_for(0.02)
        return future.result() if future.done() else None

    while time.time() < deadline:
        spin_for(0.05)
        if "/cmd_vel" in listened and "/cmd_vel" not in report["first"]:
            continue                       # the node is not up yet
        if calls:
            if not client.wait_for_services(timeout_sec=0.1):
                continue
            kind, *args = calls.pop(0)
            if kind == "list":
                r = wait(client.list_parameters(depth=0))
                report["calls"].append(["list", list(r.result.names) if r else "timeout"])
            elif kind == "get":
                r = wait(client.get_parameters(args[0]))
                report["calls"].append(["get", [value_of(v) for v in r.values] if r
                                        else "timeout"])
            elif kind == "describe":
                r = wait(client.describe_parameters(args[0]))
                report["calls"].append(["describe", [[d.name, d.read_only, d.description]
                                                     for d in r.descriptors] if r
                                        else "timeout"])
            elif kind == "set":
                r = wait(client.set_parameters([Parameter(n, value=v) for n, v in args[0]]))
                report["calls"].append(["set", [[x.successful, x.reason] for x in r.results]
                                        if r else "timeout"])
            elif kind == "wait":
                spin_for(args[0])
            continue
        stop_at = stop_at or time.time() + plan.get("after", 0.0)
        if time.time() >= stop_at:
            break
    print(json.dumps(report), flush=True)
    node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
