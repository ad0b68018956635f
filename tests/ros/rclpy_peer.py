"""A real ROS 2 node (Jazzy rclpy, rmw_fastrtps_cpp) for the DDS tests, run as a subprocess.

Reads a JSON plan from the file named by argv[1]:
  publish: [[topic, type, reliable, cdr_hex], ...]  published every 0.1 s (rclpy decodes the
           rosbags CDR first, so Fast DDS serialises the message itself)
  listen:  [[topic, type, reliable], ...]          raw subscriptions: the bytes as they arrive
  node:    [name, namespace]                       whose publishers and subscriptions to report
  expect:  {"publishers": n, "subscribers": n}     graph entries to wait for
  timeout: seconds
It runs until it has heard every listened topic, sees the node with the expected endpoints and
reads "done" on stdin (or the timeout passes), then prints one JSON line with what it received
(each topic's first sample as received and as rclpy re-serialises it after decoding) and what
the ROS graph showed.
"""

import importlib
import json
import select
import sys
import time

import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message


def get_message(msgtype):
    package, kind, name = msgtype.split("/")
    return getattr(importlib.import_module(f"{package}.{kind}"), name)


def qos(reliable):
    return QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE if reliable
                      else ReliabilityPolicy.BEST_EFFORT)


def main():
    with open(sys.argv[1]) as f:
        plan = json.load(f)
    rclpy.init()
    node = rclpy.create_node("rclpy_peer")
    publishers = []
    for topic, msgtype, reliable, data in plan["publish"]:
        cls = get_message(msgtype)
        pub = node.create_publisher(cls, topic, qos(reliable))
        publishers.append((pub, deserialize_message(bytes.fromhex(data), cls)))
    heard = {}
    for topic, msgtype, reliable in plan["listen"]:
        cls = get_message(msgtype)

        def on_raw(data, topic=topic, cls=cls):
            if topic not in heard:
                heard[topic] = {"raw": bytes(data).hex(), "rclpy": serialize_message(
                    deserialize_message(bytes(data), cls)).hex()}
        node.create_subscription(cls, topic, on_raw, qos(reliable), raw=True)
    name, namespace = plan["node"]
    deadline = time.monotonic() + plan["timeout"]
    done, last, graph = False, 0.0, {}
    while time.monotonic() < deadline:
        now = time.monotonic()
        if now - last > 0.1:
            last = now
            for pub, msg in publishers:
                pub.publish(msg)
            graph = read_graph(node, name, namespace, plan["listen"], plan["publish"])
        rclpy.spin_once(node, timeout_sec=0.02)
        if not done and select.select([sys.stdin], [], [], 0)[0]:
            done = sys.stdin.readline().strip() == "done"
        complete = (len(graph.get("publishers", [])) >= plan["expect"]["publishers"]
                    and len(graph.get("subscribers", [])) >= plan["expect"]["subscribers"])
        if done and complete and len(heard) == len(plan["listen"]):
            break
    print(json.dumps({"heard": heard, "graph": graph}), flush=True)
    node.destroy_node()
    rclpy.shutdown()


def endpoint(info):
    return {"node": info.node_name, "type": info.topic_type, "hash": str(info.topic_type_hash),
            "reliability": info.qos_profile.reliability.name,
            "durability": info.qos_profile.durability.name}


def read_graph(node, name, namespace, listened, published):
    """What rclpy's graph API says about ``namespace/name`` and the topics it shares with us."""
    graph = {"nodes": [list(n) for n in node.get_node_names_and_namespaces()]}
    if [name, namespace] not in graph["nodes"]:
        return graph
    try:
        graph["publishers"] = [[t, list(ts)] for t, ts in
                               node.get_publisher_names_and_types_by_node(name, namespace)]
        graph["subscribers"] = [[t, list(ts)] for t, ts in
                                node.get_subscriber_names_and_types_by_node(name, namespace)]
    except Exception as exc:  # the node left between the two calls
        graph["error"] = str(exc)
    graph["writers"] = {topic: [endpoint(info) for info in node.get_publishers_info_by_topic(
        topic)] for topic, *_ in listened}
    graph["readers"] = {topic: [endpoint(info) for info in node.get_subscriptions_info_by_topic(
        topic)] for topic, *_ in published}
    return graph


if __name__ == "__main__":
    main()
