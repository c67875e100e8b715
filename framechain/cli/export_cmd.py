"""``framechain export``: the log and its replay in one MCAP for Foxglove."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from framechain.cli.common import (
    add_log_arguments,
    chain_text,
    imports_set_aside,
    incomplete_chain_line,
    print_suggested_chain,
    progress_reporter,
    say_generated_robot,
    say_unattributed,
    warner,
)

DESCRIPTION = """\
Replay (and attribute) the chain of a log and write one MCAP holding the log's own messages (a LeRobot
episode, which has none: its frame tree on /tf and /tf_static, /joint_states, each camera's
/<camera>/calibration and its frames as /<camera>/video or /<camera>/image) and the replay as Foxglove
schemas: /framechain/tf (FrameTransforms of the recomputed chain),
/framechain/annotations (ImageAnnotations on the camera images: detection, projected as-run and
recomputed points, the line between them, in Foxglove's pixel convention; an as-run point off the image
ends its line at the border), /framechain/calibration (CameraCalibration: the camera model the replay used,
frame <camera>@replay, so the annotations can be shown on a log without images), /framechain/scene
(SceneUpdate: as-run vs recomputed world points and error lines) and /framechain/findings (a Log
message per finding). Open it in Foxglove: the Image panel on the image topic with the annotations
topic, the 3D panel on the scene.
"""


def register(sub: Any) -> None:
    parser = sub.add_parser("export", help="write the log plus the replay as one Foxglove MCAP",
                            description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_log_arguments(parser)
    parser.add_argument("--out", required=True, metavar="ANNOTATED.mcap", help="the MCAP to write")
    parser.add_argument("--attribute", action=argparse.BooleanOptionalAction, default=True,
                        help="attribute the error and add the findings (default: on)")
    parser.add_argument("--seed", type=int, default=0, help="bootstrap seed of the attribution (default 0)")
    parser.add_argument("--json", action="store_true", help="print the counts as one JSON object")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from framechain import pipeline
    from framechain.adapters.formats.mcap.writer import copies_messages, write_mcap_with
    from framechain.adapters.lerobot.media import encoded_frames
    from framechain.errors import FramechainError
    from framechain.sinks.foxglove_export import foxglove_messages, viewing_hints
    from framechain.sinks.foxglove_timeline import timeline_messages

    out = Path(args.out)
    if out.suffix.lower() != ".mcap":
        raise FramechainError(f"--out {out}: an export is an MCAP file; name it *.mcap")
    quiet = args.quiet or args.json
    with imports_set_aside(), progress_reporter(quiet, "exporting") as progress:
        made = pipeline.run(args.log, args.chain, episode=args.episode, robot=args.robot, attribute=args.attribute,
                            seed=args.seed, progress=progress, warn=warner("export"))
        say_generated_robot(made, "export", out.with_suffix(".robot.yaml"))
        say_unattributed(made, "export")  # the recomputed chain is still worth exporting
        extra = foxglove_messages(made)
        if not copies_messages(made.path):  # a dataset: its frame tree, joints and cameras are the log
            content, notes = timeline_messages(made, encoded_frames)
            extra += content
            for note in notes:
                print(f"framechain export: {note}", file=sys.stderr)
        if not extra and not copies_messages(made.path):
            raise FramechainError(f"{made.path}: nothing to export (no transforms, joint states, cameras or replay)")
        if progress is not None:
            progress(f"writing {out}")
        counts = write_mcap_with(made.path, out, extra)
        if not counts.copied and not counts.added:
            out.unlink(missing_ok=True)
            raise FramechainError(f"{made.path}: nothing to export: the log has no messages and nothing was "
                                  "replayed; no file written")
    if made.chain_suggested:
        print_suggested_chain(made.suggestion or made.chain, quiet, args.log)
    replay_counts = made.replay.counts()
    if args.json:
        print(json.dumps({"out": str(out), "copied": counts.copied, "added": counts.added,
                          "observations": replay_counts, "findings": len(made.findings),
                          "chain_incomplete": incomplete_chain_line(made)}))
        return 0
    print(f"log           {made.path}")
    print(f"chain         {chain_text(made)}{' (suggested)' if made.chain_suggested else ''}")
    incomplete = incomplete_chain_line(made)
    if incomplete is not None:
        print(f"note          {incomplete}")
    print(f"copied        {sum(counts.copied.values())} messages on {len(counts.copied)} topics")
    for topic, n in sorted(counts.added.items()):
        print(f"added         {n:>6} on {topic}")
    print(f"observations  {replay_counts['total']} total, {replay_counts['replayed']} replayed")
    for hint in viewing_hints(made, counts.added):
        print(f"annotations   {hint}")
    print(f"wrote         {out} (open it in Foxglove)", file=sys.stdout)
    return 0
