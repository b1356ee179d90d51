"""Helpers to attach the MCAP recorder to an in-process graph."""
from __future__ import annotations

from collections.abc import Callable, Sequence

from rclpy.context import Context
from rclpy.node import Node
from rclpy.parameter import Parameter

__all__ = ["recorder_factory"]


def recorder_factory(path: str, topics: Sequence[str] | None = None,
                     sim_time: bool = True) -> Callable[[Context], Node]:
    """A factory for :class:`~hasel_sysid.recorder_node.RecorderNode` writing ``path``."""
    def make(context: Context) -> Node:
        from hasel_sysid.recorder_node import RecorderNode

        return RecorderNode(path, topics, context=context,
                            parameter_overrides=[Parameter("use_sim_time", value=sim_time)])
    return make
