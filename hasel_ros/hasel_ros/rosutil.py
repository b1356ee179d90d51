"""ROS plumbing shared by the toolkit's nodes: QoS, time stamps, parameters, diagnostics, main().

Its own package (hasel_ros), below every node package: hasel_driver, hasel_control,
sim_plant and hasel_sysid import it and declare it. Arithmetic and decisions stay in the
core library ``hasel``.
"""
from __future__ import annotations

import array
import math
import sys
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import rclpy
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from hasel.timeconv import ns_to_s, s_to_ns, s_to_stamp, stamp_to_ns, stamp_to_s
from hasel.topics import QosSpec, topic

__all__ = ["qos", "topic_qos", "message_class", "to_stamp", "from_stamp", "stamp_ns", "now_s", "declare",
           "diagnostic", "run_node", "validate_with", "float64_array", "Deadline"]


def qos(spec: QosSpec) -> QoSProfile:
    """rclpy profile of a :class:`hasel.topics.QosSpec`."""
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=spec.depth,
        reliability=ReliabilityPolicy.RELIABLE if spec.reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if spec.transient_local else DurabilityPolicy.VOLATILE)


def topic_qos(name: str) -> QoSProfile:
    """rclpy profile of one of the graph's default topics (see :mod:`hasel.topics`)."""
    return qos(topic(name).qos)


def message_class(type_name: str) -> type:
    """The Python class of a message type named ``pkg/msg/Type`` (or ``pkg/Type``)."""
    import importlib

    parts = type_name.split("/")
    if len(parts) == 2:
        parts = [parts[0], "msg", parts[1]]
    if len(parts) != 3 or not all(parts):
        raise ValueError(f"not a message type name: {type_name!r}")
    try:
        return getattr(importlib.import_module(f"{parts[0]}.{parts[1]}"), parts[2])
    except (ImportError, AttributeError) as err:
        raise ValueError(f"message type {type_name} is not installed ({err})") from err


def to_stamp(t_s: float) -> Time:
    """Seconds (float) -> builtin_interfaces/Time, rounded to the nearest nanosecond."""
    sec, nanosec = s_to_stamp(t_s)
    return Time(sec=sec, nanosec=nanosec)


def from_stamp(stamp: Time) -> float:
    """builtin_interfaces/Time -> seconds (float; the same float as the core's ``ns_to_s`` of its ns)."""
    return stamp_to_s(stamp.sec, stamp.nanosec)


def stamp_ns(stamp: Time) -> int:
    """builtin_interfaces/Time -> integer nanoseconds (exact: what the core's decisions compare)."""
    return stamp_to_ns(stamp.sec, stamp.nanosec)


def now_s(node: Node) -> float:
    """The node's clock (ROS time; simulated under ``use_sim_time``), float seconds."""
    return ns_to_s(node.get_clock().now().nanoseconds)


def float64_array(values) -> array.array:
    """A float64[] message field's value from a numpy array (or any float sequence), units kept.

    rosidl stores such fields as ``array.array('d')`` and converts anything else
    element by element; one copy of the bytes is about ten times cheaper for the
    plant's 50-sample batches, published every tick.
    """
    out = array.array("d")
    out.frombytes(np.ascontiguousarray(values, dtype=np.float64).tobytes())
    return out


class Deadline:
    """A timer that fires only once ``timeout_s`` has passed without :meth:`feed`, then every ``repeat_s``.

    A watchdog that polls an age every loop period costs one executor callback per
    period even while all is well; in lockstep simulation that is one of a handful of
    callbacks per tick. This timer is pushed back by each feed instead, so it runs
    only when something is late. It fires at the first instant strictly later than
    ``timeout_s`` after the last feed (the same instant as a poll of ``age >
    timeout`` at the period's ticks), then every ``repeat_s`` until the next feed.
    It is disarmed until the first feed. Times in s, on the node's clock (ROS time,
    simulated under ``use_sim_time``).
    """

    def __init__(self, node: Node, timeout_s: float, repeat_s: float, callback: Callable[[], None]) -> None:
        self._callback = callback
        self._repeat_ns = max(1, s_to_ns(repeat_s))
        self._late = False  # True once the timeout has passed: firing every repeat_s
        self.timer = node.create_timer(repeat_s, self._fire)
        self.timer.cancel()
        self.timeout_s = timeout_s

    @property
    def timeout_s(self) -> float:
        """Time without a feed before the first call, s."""
        return ns_to_s(self._timeout_ns - 1)

    @timeout_s.setter
    def timeout_s(self, value: float) -> None:
        # one nanosecond more: the call comes strictly after the timeout, as `age > timeout` does
        self._timeout_ns = max(1, s_to_ns(value)) + 1
        if not self._late:
            self.timer.timer_period_ns = self._timeout_ns

    def feed(self) -> None:
        """Something fresh arrived: the next call is ``timeout_s`` from now."""
        if self._late:
            self.timer.timer_period_ns = self._timeout_ns
            self._late = False
        self.timer.reset()  # also re-arms the timer, disarmed until the first feed

    def _fire(self) -> None:
        if not self._late:
            self._late = True
            self.timer.timer_period_ns = self._repeat_ns
            self.timer.reset()  # the next call one repeat from now, not one timeout
        self._callback()


def declare(node: Node, name: str, default: Any, description: str, *,
            lo: float | None = None, hi: float | None = None, read_only: bool = False) -> Any:
    """Declare a parameter with a descriptor (and a range for numbers); return its value.

    ``lo``/``hi`` become a FloatingPointRange (floats) or IntegerRange (ints), which
    rclpy enforces on every later set.
    """
    desc = ParameterDescriptor(description=description, read_only=read_only)
    if lo is not None and hi is not None:
        if isinstance(default, bool):
            pass
        elif isinstance(default, int):
            desc.integer_range = [IntegerRange(from_value=int(lo), to_value=int(hi), step=0)]
        elif isinstance(default, float):
            desc.floating_point_range = [FloatingPointRange(from_value=float(lo), to_value=float(hi), step=0.0)]
    return node.declare_parameter(name, default, desc).value


def validate_with(check: Callable[[dict[str, Any]], None]) -> Callable[[list], SetParametersResult]:
    """A parameter callback that accepts a change only if ``check(new values)`` does not raise.

    ``check`` gets {name: value} of the parameters being set; any exception's text is
    returned to the caller as the reason of the rejection.
    """
    def callback(params: list) -> SetParametersResult:
        try:
            check({p.name: p.value for p in params})
        except Exception as err:  # noqa: BLE001 - the reason goes back to the caller
            return SetParametersResult(successful=False, reason=str(err))
        return SetParametersResult(successful=True)
    return callback


def diagnostic(node: Node, level: bytes, message: str, t_s: float, **values: Any) -> DiagnosticArray:
    """A one-status DiagnosticArray named after ``node`` (level: DiagnosticStatus.OK/WARN/ERROR)."""
    st = DiagnosticStatus(level=level, name=node.get_fully_qualified_name(), message=message,
                          hardware_id="hasel")
    st.values = [KeyValue(key=k, value=(f"{v:.6g}" if isinstance(v, float) and math.isfinite(v) else str(v)))
                 for k, v in values.items()]
    arr = DiagnosticArray(status=[st])
    arr.header.stamp = to_stamp(t_s)
    return arr


def _stop_on_signals(wake: Callable[[], None]) -> tuple[dict[str, int], Callable[[], None]]:
    """Handle SIGINT (unless inherited as ignored), SIGTERM and SIGHUP alike for a node's main.

    rclpy's own handlers would shut the context down inside the signal, so a node's
    ``on_shutdown`` could no longer publish (the amplifier's last 0 kV) and the exit code
    would not say which signal came. Here a signal is only recorded; the signal module's
    wake-up descriptor, written by the C-level handler whatever the main thread is doing,
    is read by a small thread that calls ``wake`` (a guard condition of the executor), so a
    spin blocked in the middleware returns at once. Returns the state (``signum``, 0 until a
    signal arrives) and a function that puts everything back.
    """
    import os
    import signal
    import threading

    state = {"signum": 0}
    r, w = os.pipe()
    os.set_blocking(w, False)

    def handler(signum: int, frame) -> None:
        del frame
        if not state["signum"]:
            state["signum"] = int(signum)

    previous = {}
    for name in ("SIGINT", "SIGTERM", "SIGHUP"):
        sig = getattr(signal, name, None)
        if sig is None or (sig == signal.SIGINT and signal.getsignal(sig) == signal.SIG_IGN):
            continue  # started in a script's background: SIGINT stays ignored, as the shell meant
        previous[sig] = signal.signal(sig, handler)
    old_fd = signal.set_wakeup_fd(w, warn_on_full_buffer=False)

    def reader() -> None:
        try:
            _read_until_closed()
        finally:
            os.close(r)  # here, not in restore(): never under a read still running

    def _read_until_closed() -> None:
        while True:
            try:
                data = os.read(r, 64)
            except OSError:
                return
            if not data:  # restore() closed the writing end
                return
            for b in data:  # the byte is the signal number: recorded here too, in case the main thread sleeps
                if not state["signum"] and b in previous:
                    state["signum"] = int(b)
            try:
                wake()
            except Exception:  # noqa: BLE001 - the guard condition may be gone at exit
                return

    threading.Thread(target=reader, name="hasel-stop-signals", daemon=True).start()

    def restore() -> None:
        signal.set_wakeup_fd(old_fd)
        for sig, h in previous.items():
            signal.signal(sig, h if h is not None else signal.SIG_DFL)
        os.close(w)  # the reader sees end of file, closes its end and ends

    return state, restore


def _flush_publishers(node: Node, timeout_s: float = 1.0) -> None:
    """Wait (at most ``timeout_s`` s in all) until reliable subscribers acknowledged what was published.

    Destroying a node right after its last publish can drop that message before DDS delivered
    it; the last message of a stopped amplifier is its 0 kV command, which must arrive.
    """
    from rclpy.duration import Duration

    end = time.monotonic() + timeout_s
    for pub in list(node.publishers):
        left = end - time.monotonic()
        if left <= 0:
            return
        try:
            pub.wait_for_all_acked(Duration(nanoseconds=s_to_ns(left)))
        except Exception:  # noqa: BLE001 - a context already gone at exit: nothing left to flush
            return


def run_node(factory: Callable[[], Node], args: Sequence[str] | None = None) -> int:
    """Standard Jazzy main: init, spin one node, clean shutdown on SIGINT, SIGTERM or SIGHUP.

    A stop signal ends the spin; the node's ``on_shutdown`` then runs while the ROS context
    is still valid (the amplifier commands 0 kV, the recorder closes its file), the node is
    destroyed, and the exit code is 128 + the signal number, as for the ``hasel`` commands
    (:mod:`hasel.interrupt`). SIGINT stays ignored when the node was started with it ignored
    (in a script's background).

    A bad parameter at start (out of range, wrong type, unsafe, unparsable ``--ros-args``)
    is one line on stderr and exit code 2; the node is never built, so nothing is commanded.
    """
    from rclpy.exceptions import ParameterException
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    from hasel.errors import BadInputError

    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except Exception as err:  # noqa: BLE001 - e.g. RCLError for a malformed -p NAME:=VALUE
        sys.stderr.write(f"error: bad arguments: {str(err).splitlines()[0] if str(err) else type(err).__name__}\n")
        return 2
    wake_gc: list = []
    stop, restore = _stop_on_signals(lambda: [g.trigger() for g in wake_gc])
    node = None
    executor = None
    code = 0
    try:
        node = factory()
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        wake_gc.append(node.create_guard_condition(lambda: None))
        while rclpy.ok() and not stop["signum"]:
            executor.spin_once(timeout_sec=0.5)  # the guard condition wakes it at a signal; 0.5 s is a backstop
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (BadInputError, ParameterException) as err:  # a start-up error is one line, not a traceback
        sys.stderr.write(f"error: {err}\n")
        code = 2
    except Exception as err:  # noqa: BLE001 - a real failure: one line, exit 1
        if not stop["signum"]:
            sys.stderr.write(f"error: {type(err).__name__}: {err}\n")
            code = 1
    finally:
        wake_gc.clear()
        if node is not None:
            shutdown = getattr(node, "on_shutdown", None)
            if shutdown is not None:
                shutdown()  # context still valid: the last command (0 kV) goes out, files close
            _flush_publishers(node)
            if executor is not None:
                executor.remove_node(node)
            node.destroy_node()
        restore()
        rclpy.try_shutdown()
    if stop["signum"] and code != 2:
        import signal

        sys.stderr.write(f"stopped by {signal.Signals(stop['signum']).name}\n")
        return 128 + stop["signum"]
    return code
