"""The node's log on /rosout: Python log records as rcl_interfaces/Log, as every ROS 2 node
publishes its log (rcl's /rosout QoS: reliable, transient local, depth 1000), besides the
terminal."""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from typing import Any

from companion.ros.messages import message

#: Python's log levels as rcl_interfaces/Log's (DEBUG 10 ... FATAL 50; the same numbers).
LEVELS = {logging.DEBUG: 10, logging.INFO: 20, logging.WARNING: 30, logging.ERROR: 40,
          logging.CRITICAL: 50}


def logger_name(node_name: str, namespace: str) -> str:
    """The name rcl gives a node's logger: its namespace and name joined by dots
    (``/robot1`` + ``companion`` -> ``robot1.companion``)."""
    return ".".join([*namespace.strip("/").split("/"), node_name]).lstrip(".")


class RosoutHandler(logging.Handler):
    """Publishes every record it handles as rcl_interfaces/Log with ``publish``, stamped by
    ``stamp()`` (a ``builtin_interfaces/Time``), named ``name``. A failure to publish is
    dropped (a log record must not stop the node), and a record raised while publishing one
    is not sent again."""

    def __init__(self, store: Any, publish: Callable[[Any], None], name: str,
                 stamp: Callable[[], Any]):
        super().__init__()
        self.store, self.publish, self.name, self.stamp = store, publish, name, stamp
        self._inside = threading.local()

    def emit(self, record: logging.LogRecord) -> None:
        if getattr(self._inside, "busy", False):
            return
        self._inside.busy = True
        try:
            level = LEVELS.get(record.levelno, 50 if record.levelno > 50 else 10)
            self.publish(message(self.store, "rcl_interfaces/msg/Log", stamp=self.stamp(),
                                 level=level, name=self.name, msg=record.getMessage(),
                                 file=record.pathname, function=record.funcName,
                                 line=record.lineno))
        except Exception:
            pass
        finally:
            self._inside.busy = False
