"""Open the transport a node's ``ros`` parameters name (DDS or Zenoh), importing only it."""

from __future__ import annotations

from companion.ros.settings import RosParams
from companion.ros.transport import Transport


def open_transport(ros: RosParams, node_name: str | None = None) -> Transport:
    """A transport for the node ``node_name`` (default ``ros.node_name``) in ``ros.namespace``
    on ``ros.domain_id``, speaking ``ros.distro``'s types."""
    name = node_name or ros.node_name
    if ros.transport == "dds":
        from companion.ros.dds import DdsTransport

        return DdsTransport(node_name=name, namespace=ros.namespace, domain_id=ros.domain_id,
                            distro=ros.distro)
    from companion.ros.zenoh import ZenohTransport

    return ZenohTransport(node_name=name, namespace=ros.namespace, domain_id=ros.domain_id,
                          distro=ros.distro, connect=[ros.zenoh_connect])
