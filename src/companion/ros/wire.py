"""Open the transport a node's ``ros`` parameters name (DDS or Zenoh), importing only it."""

from __future__ import annotations

from companion.errors import TransportError
from companion.ros.settings import RosParams
from companion.ros.transport import Transport


def open_transport(ros: RosParams, node_name: str | None = None, robot: bool = False
                   ) -> Transport:
    """A transport for the node ``node_name`` (default ``ros.node_name``) in ``ros.namespace``
    on ``ros.domain_id``, speaking ``ros.distro``'s types. With Zenoh, a ``robot`` (the
    simulated one) is also the router at ``ros.zenoh_connect``, as a robot runs rmw_zenohd."""
    try:
        return _open(ros, node_name or ros.node_name, robot)
    except (ConnectionError, OSError) as exc:
        raise TransportError(f"{ros.transport}: {exc}".replace("\n", " ")) from None


def _open(ros: RosParams, name: str, robot: bool) -> Transport:
    if ros.transport == "dds":
        from companion.ros.dds import DdsTransport

        return DdsTransport(node_name=name, namespace=ros.namespace, domain_id=ros.domain_id,
                            distro=ros.distro)
    from companion.ros.zenoh import ZenohTransport

    if robot:
        return ZenohTransport(node_name=name, namespace=ros.namespace, domain_id=ros.domain_id,
                              distro=ros.distro, connect=[], listen=[ros.zenoh_connect],
                              mode="router")
    return ZenohTransport(node_name=name, namespace=ros.namespace, domain_id=ros.domain_id,
                          distro=ros.distro, connect=[ros.zenoh_connect])
