"""`choreo frames play N | stop | restore | status`: a frame's bytes, for checking by hand."""

from __future__ import annotations

import argparse

from choreo.errors import UsageError


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "frames",
        help="print an RCB-4 frame as hex bytes",
        description="Print the exact bytes choreo sends for a frame, lowercase hex on one line.",
    )
    parser.add_argument("kind", choices=["play", "stop", "restore", "status"], help="which frame")
    parser.add_argument("motion", nargs="?", help="motion slot 0..119 (play only)")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from choreo import protocol

    if args.kind != "play":
        if args.motion is not None:
            raise UsageError(f"frames {args.kind}: takes no motion number")
        print(protocol.frame_for(args.kind).hex)
        return 0
    if args.motion is None:
        raise UsageError("frames play: give a motion number 0..119, e.g. `choreo frames play 3`")
    try:
        motion = int(args.motion, 10)
    except ValueError:
        raise UsageError(f"frames play: motion {args.motion!r} is not a whole number 0..119") from None
    print(protocol.play_frame(motion).hex)
    return 0
