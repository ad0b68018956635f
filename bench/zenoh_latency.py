"""Measure the Zenoh transport's one-way latency on loopback, through rmw_zenoh's topology.

    python bench/zenoh_latency.py [N]

A router (a Zenoh session in router mode on 127.0.0.1) and two ZenohTransports connected to
it; one publishes a geometry_msgs/Twist, the other's callback stops the clock; N (default
1000) messages one at a time. Prints the median, 99th percentile and maximum from the
publish call to the callback, including CDR serialisation and deserialisation.
"""

from __future__ import annotations

import json
import socket
import sys
import threading
import time

import numpy as np
import zenoh

from companion.ros.zenoh import ZenohTransport

TWIST = "geometry_msgs/msg/Twist"


def main(n: int = 1000) -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    config = zenoh.Config()
    for key, value in {"mode": "router", "listen/endpoints": [f"tcp/127.0.0.1:{port}"],
                       "scouting/multicast/enabled": False}.items():
        config.insert_json5(key, json.dumps(value))
    router = zenoh.open(config)
    endpoint = [f"tcp/127.0.0.1:{port}"]
    try:
        with ZenohTransport("sender", connect=endpoint) as a, \
                ZenohTransport("receiver", connect=endpoint) as b:
            types = a.typestore.types
            vec = types["geometry_msgs/msg/Vector3"]
            msg = types[TWIST](vec(0.5, 0.0, 0.0), vec(0.0, 0.0, 0.1))
            arrived = threading.Event()
            stamps: list[float] = []
            b.subscribe("/latency", TWIST, lambda m: (stamps.append(time.perf_counter()),
                                                      arrived.set()))
            publish = a.publisher("/latency", TWIST)
            while not arrived.is_set():          # until the subscription has reached a
                publish(msg)
                arrived.wait(0.05)
            times = []
            for _ in range(n):
                arrived.clear()
                start = time.perf_counter()
                publish(msg)
                if arrived.wait(1.0):
                    times.append(stamps[-1] - start)
                time.sleep(0.001)
    finally:
        router.close()
    ms = 1e3 * np.array(times)
    print(f"{len(ms)}/{n} received; publish -> callback: median {np.median(ms):.3f} ms, "
          f"p99 {np.percentile(ms, 99):.3f} ms, max {ms.max():.3f} ms")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 1000)
