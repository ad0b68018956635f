"""Open the transport a node's ``ros`` parameters name (DDS, Zenoh or rclpy), importing only
it."""

from __future__ import annotations

import os

from companion.errors import TransportError
from companion.ros.settings import RosParams
from companion.ros.transport import Transport, ros_domain_id


def domain_of(ros: RosParams) -> tuple[int, str]:
    """The ROS domain the node joins and where it comes from: ``ros.domain_id`` when set (a
    parameter file or ``--domain-id``), else ``$ROS_DOMAIN_ID``, else 0."""
    if ros.domain_id is not None:
        return ros.domain_id, "ros.domain_id"
    domain = ros_domain_id(None)
    return domain, "ROS_DOMAIN_ID" if os.environ.get("ROS_DOMAIN_ID") else \
        "the default: ROS_DOMAIN_ID is not set"


def open_transport(ros: RosParams, node_name: str | None = None, robot: bool = False
                   ) -> Transport:
    """A transport for the node ``node_name`` (default ``ros.node_name``) in ``ros.namespace``
    on the domain of :func:`domain_of`, speaking ``ros.distro``'s types. With Zenoh, a
    ``robot`` (the simulated one) is also the router at ``ros.zenoh_connect``, as a robot runs
    rmw_zenohd."""
    try:
        return _open(ros, node_name or ros.node_name, domain_of(ros)[0], robot)
    except (ConnectionError, OSError) as exc:
        raise TransportError(f"{ros.transport}: {exc}".replace("\n", " ")) from None


def _open(ros: RosParams, name: str, domain: int, robot: bool) -> Transport:
    if ros.transport == "rclpy":
        from companion.ros.rclpy_transport import RclpyTransport

        return RclpyTransport(node_name=name, namespace=ros.namespace, domain_id=domain,
                              distro=ros.distro)
    if ros.transport == "dds":
        from companion.ros.dds import DdsTransport

        return DdsTransport(node_name=name, namespace=ros.namespace, domain_id=domain,
                            distro=ros.distro)
    from companion.ros.zenoh import ZenohTransport

    if robot:
        return ZenohTransport(node_name=name, namespace=ros.namespace, domain_id=domain,
                              distro=ros.distro, connect=[], listen=[ros.zenoh_connect],
                              mode="router")
    return ZenohTransport(node_name=name, namespace=ros.namespace, domain_id=domain,
                          distro=ros.distro, connect=[ros.zenoh_connect])
