"""`choreo devices`: the audio outputs the music can play on (`choreo run --audio-device`)."""

from __future__ import annotations

import argparse
import json


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "devices",
        help="list the audio outputs a show's music can play on",
        description="List the audio outputs miniaudio finds, numbered as `choreo run --audio-device` "
        "takes them (a number, or any unique part of a name). `null` is always there: silent, but "
        "it keeps the music's time, as on a machine with no sound card.",
    )
    parser.add_argument("--json", action="store_true", help="one JSON object: the outputs and the backend")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from choreo.cli.terminal import print_fitted
    from choreo.music.player import NULL_DEVICE, outputs

    found = outputs()
    if args.json:
        print(json.dumps({"outputs": [{"number": o.number, "name": o.name, "backend": o.backend} for o in found]},
                         ensure_ascii=False))
        return 0
    real = [o for o in found if o.name != NULL_DEVICE]
    if not real:
        print("no audio outputs found (no sound system answers): music shows play silent on null")
    for output in real:
        print_fitted(f"{output.number:>3}  {output.name} ({output.backend})")
    print_fitted(f"{NULL_DEVICE:>4} silent, keeps the music's time (miniaudio's null backend)")
    return 0
