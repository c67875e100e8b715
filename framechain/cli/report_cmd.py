"""``framechain report``: attribute LOG and write the HTML and Markdown reports."""

from __future__ import annotations

import argparse
from typing import Any

from framechain.cli import attribute_cmd
from framechain.cli.common import add_log_arguments, non_negative_int


def register(sub: Any) -> None:
    parser = sub.add_parser(
        "report",
        help="attribute a log and write report.html (self-contained) and report.md",
        description="Same analysis as `attribute`, written as one self-contained HTML page and Markdown: the "
        "verdict, the findings with intervals and fixes, plots, and provenance.",
    )
    add_log_arguments(parser)
    parser.add_argument("--out", required=True, metavar="DIR", help="output directory")
    parser.add_argument("--seed", type=int, default=0, help="bootstrap seed (default 0)")
    parser.add_argument("--bootstrap", type=non_negative_int, default=30,
                        help="bootstrap resamples, 0 for none (default 30)")
    parser.add_argument("--json", action="store_true", help="print attribution.json to stdout")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    return attribute_cmd.run(args, default_formats=["json", "md", "html"])
