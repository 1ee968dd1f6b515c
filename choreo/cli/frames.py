"""`choreo frames play N | stop | counter | restore | status`: a frame's bytes, for checking by hand."""

from __future__ import annotations

import argparse

from choreo.errors import UsageError
from choreo.wire.layouts import DEFAULT_LAYOUT, HTH4_22, LAYOUT_NAMES, SEED, layout_named
from choreo.wire.protocol import BAUD_CODES, DEFAULT_BAUD, MOTION_SLOTS, baud_refusal, check_motion, spell_bauds

KINDS = ("play", "stop", "counter", "restore", "status")


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "frames",
        help="print an RCB-4 frame as hex bytes",
        description="Print the exact bytes choreo sends for a frame, lowercase hex on one line. "
        "stop and restore are the seed layout's stop-and-save and restore frames (at --baud, "
        "whose code they carry in the config word's bits 7-6) or hth4-2.2's suspend and resume "
        "(made from --config, the board's config word); counter is hth4-2.2's program counter write.",
    )
    parser.add_argument("kind", choices=KINDS, help="which frame")
    parser.add_argument("motion", nargs="?", help=f"motion slot 0..{MOTION_SLOTS - 1} (play only)")
    parser.add_argument("--layout", default=DEFAULT_LAYOUT, choices=LAYOUT_NAMES,
                        help=f"the board's memory layout (default {DEFAULT_LAYOUT})")
    parser.add_argument("--baud", type=int, default=DEFAULT_BAUD, help=spell_bauds("or", mark_default=True))
    parser.add_argument("--config", metavar="WORD", help="hth4-2.2: the board's config word, e.g. "
                        "0x821b (default: that one, what an HTH4 2.2+ project saves)")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    layout = layout_named(args.layout)
    if args.baud not in BAUD_CODES:
        raise UsageError(baud_refusal(args.baud, "--baud"))
    config = _config(args.config, layout.reads_config)
    if args.kind != "play":
        _no_motion(args)
    if args.kind == "status":
        print(layout.status.hex)
        return 0
    motion = _motion(args) if args.kind == "play" else 0
    frames = {frame.kind.value: frame for frame in layout.play_sequence(motion, config, args.baud)}
    if args.kind not in frames:
        raise UsageError(f"frames {args.kind}: the {layout.name} layout sends no {args.kind} frame "
                         f"(it sends {', '.join(frames)})")
    print(frames[args.kind].hex)
    return 0


def _config(text: str | None, used: bool) -> int | None:
    if text is None:
        return None
    if not used:
        raise UsageError(f"--config: the {SEED.name} layout's frames are fixed; "
                         f"--config is for --layout {HTH4_22.name}")
    try:
        word = int(text, 0)
    except ValueError:
        word = -1
    if not 0 <= word <= 0xFFFF:
        raise UsageError(f"--config {text}: give the 16-bit config word, e.g. 0x821b")
    return word


def _no_motion(args: argparse.Namespace) -> None:
    if args.motion is not None:
        raise UsageError(f"frames {args.kind}: takes no motion number")


def _motion(args: argparse.Namespace) -> int:
    if args.motion is None:
        raise UsageError(f"frames play: give a motion number 0..{MOTION_SLOTS - 1}, e.g. `choreo frames play 3`")
    try:
        motion = int(args.motion, 10)
    except ValueError:
        raise UsageError(f"frames play: motion {args.motion!r} is not a whole number 0..{MOTION_SLOTS - 1}") from None
    return check_motion(motion)
