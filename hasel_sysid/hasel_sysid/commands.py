"""The ``hasel`` subcommands that drive the node graph, declared for the core's command line.

``setup.py`` lists each under the ``hasel.commands`` entry-point group; ``hasel``
imports this module to list and parse them (it imports no rclpy: their work, in the
modules named by ``target``, is imported only when the command runs).
"""
from __future__ import annotations

import argparse

from hasel.cli import Command
from hasel.outputs import Output
from hasel.validate import seed

__all__ = ["STEPS", "COMPARE", "CALIBRATE", "CHIRP", "RECORD", "REPLAY", "DEMO"]


def _demo_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", default="out/demo", help="directory for the demo's files (default out/demo)")
    p.add_argument("--quick", action="store_true", help="shorter runs (for CI smoke tests)")


def _steps_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--sequence", default="2,4,6,4,2", help="stroke references, mm, comma-separated (default 2,4,6,4,2)")
    p.add_argument("--hold", type=float, default=1.0, help="seconds per reference (default 1)")
    p.add_argument("--feedback", choices=["laser", "strain"], default="laser", help="feedback sensor (default laser)")
    p.add_argument("--plant", default="nominal", help="plant variant (default nominal)")
    p.add_argument("--calibration", default=None, help="strain-sensor calibration YAML (from hasel calibrate)")
    p.add_argument("--gains", default=None, metavar="GAINS.yaml", help="controller gains (parameter file, hasel tune)")
    p.add_argument("--seed", type=seed, default=0, help="noise seed, 0 .. 2^31-1 (default 0)")
    p.add_argument("--record", metavar="FILE.mcap", default=None, help="record every topic to this MCAP file")
    p.add_argument("--json", metavar="FILE", default=None, help="write the step metrics as JSON")
    p.add_argument("--plot", metavar="FILE.png", default=None, help="write a plot of the run")


def _calibrate_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--points", default="2,3,4,5,6,7", help="strokes to hold, mm (default 2,3,4,5,6,7)")
    p.add_argument("--hold", type=float, default=1.0, help="seconds per point (default 1)")
    p.add_argument("--degree", type=int, choices=[1, 2, 3], default=1, help="polynomial degree (default 1: a line)")
    p.add_argument("--plant", default="nominal", help="plant variant (default nominal)")
    p.add_argument("--seed", type=seed, default=0, help="noise seed, 0 .. 2^31-1 (default 0)")
    p.add_argument("--out", default="calibration.yaml", help="calibration YAML to write (default calibration.yaml)")


def _record_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("-o", "--output", required=True, metavar="FILE.mcap", help="MCAP file to write")
    p.add_argument("--topics", default="", help="comma-separated topics (default: all, discovered as they appear)")
    p.add_argument("--duration", type=float, default=None, help="stop after this many seconds (default: Ctrl-C)")


def _replay_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", metavar="FILE", help="MCAP file to replay")
    p.add_argument("--rate", type=float, default=1.0, help="speed factor of the recorded timing (0: as fast as possible)")
    p.add_argument("--topics", default="", help="comma-separated topics to replay (default: all)")
    p.add_argument("--remap", action="append", metavar="FROM:=TO", help="publish a topic under another name")
    p.add_argument("--clock", action="store_true", help="also publish /clock from the log times")
    p.add_argument("--wait", type=float, default=1.0, help="seconds for discovery before the first message")


STEPS = Command("steps", "closed-loop step test through the node graph on the simulated plant",
                _steps_args, "hasel_sysid.steps:run", True,
                (Output("record"), Output("json"), Output("plot")), ("calibration",))
COMPARE = Command("compare", "a measured closed-loop log against simulated plants: steps and NRMSE per plant",
                  "hasel_sysid.compare:add_arguments", "hasel_sysid.compare:run", True,
                  (Output("json"), Output("plot")))
CALIBRATE = Command("calibrate", "strain-sensor calibration against the laser (1 mm steps, 2-7 mm)",
                    _calibrate_args, "hasel_sysid.calibrate:run", True, (Output("out"),))
CHIRP = Command("chirp", "the paper's identification experiment (chirps on DC offsets), recorded to MCAP",
                "hasel_sysid.chirp:add_arguments", "hasel_sysid.chirp:run", True, (Output("out"),))
RECORD = Command("record", "record topics of the running graph to an MCAP file (rosbag2 layout)",
                 _record_args, "hasel_sysid.replay:run_record", True, (Output("output"),))
REPLAY = Command("replay", "publish a recorded MCAP file back into the graph", _replay_args,
                 "hasel_sysid.replay:run_replay", True)
DEMO = Command("demo", "the end-to-end demo that `make demo` runs", _demo_args, "hasel_sysid.demo:run", True)
