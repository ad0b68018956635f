"""companion on ROS 2: the wire protocols (DDS, Zenoh) without a ROS install, the node and the
simulated robot. Message types, CDR and type hashes come from one source, rosbags' typestore
(:mod:`companion.ros.messages`); transports carry those messages (:mod:`companion.ros.transport`).
"""
