"""The HTML reports' words and style: long frame names and commands wrap at their joints, and a findings
table of long names fits a 1280 px window (measured in headless Chromium where it is installed)."""

from __future__ import annotations

import html
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from framechain.sinks.document import code_spans
from framechain.sinks.text import CSS, LONG_WORD, breakable
from tests.helpers.realdata import ARUCO_IMAGES_BAG


def _plain(marked: str) -> str:
    """The text a reader copies: tags dropped, entities decoded."""
    return html.unescape(re.sub(r"<[^>]+>", "", marked))


def test_long_words_break_at_their_joints() -> None:
    assert breakable("t265_fisheye1_optical_frame") == "t265_<wbr>fisheye1_<wbr>optical_<wbr>frame"
    assert breakable("inverted[base_link->camera_link].") == "inverted[<wbr>base_<wbr>link-&gt;<wbr>camera_<wbr>link]."
    assert breakable("camera_to_body") == "camera_to_body"  # shorter than LONG_WORD: whole
    assert len("camera_to_body") < LONG_WORD <= len("t265_fisheye1_optical_frame")
    assert breakable("a < b & c") == "a &lt; b &amp; c"


def test_commands_keep_their_flags_whole() -> None:
    fix = ("use the recorded base_link -> camera_link, i.e. `ros2 run tf2_ros static_transform_publisher --x 0.3000 "
           "--frame-id base_link --child-frame-id t265_fisheye1_optical_frame`.")
    marked = code_spans(fix, wrap=True)
    code = re.search(r"<code>(.*)</code>", marked)
    assert code is not None
    assert "<span class='nw'>--child-frame-id</span>" in code.group(1)  # a browser would break after a hyphen
    assert "static_<wbr>transform_<wbr>publisher" in code.group(1)
    assert _plain(marked) == fix.replace("`", "")  # what is copied is the command as written
    assert "break-all" not in CSS  # which broke commands anywhere, mid-word
    assert ".nw{white-space:nowrap}" in CSS


def _chromium() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")


@pytest.mark.skipif(_chromium() is None, reason="no headless Chromium to measure the page")
def test_a_table_of_long_frame_names_fits_the_page(tmp_path: Path) -> None:
    """Eleven columns of long frame names and a command (a rig's findings table): the page stays 1280 px wide
    at a 1280 px window, and the table needs no scrolling of its own."""
    frame = "left_camera_rig_fisheye_optical_frame_with_a_long_name"
    cells = [f"rotation_error_of_{frame}", "camera_to_body", frame, f"3.00 deg about -y of {frame}",
             "2.000 .. 4.000 deg", "99%", "1355.4 mm", "1.00", "strong",
             f"With rotation_error in the chain, the points of {frame} depart: inverted[{frame}->{frame}].",
             f"Use `ros2 run tf2_ros static_transform_publisher --x 0.3 --frame-id base_link --child-frame-id "
             f"{frame}`."]
    row = "".join(f"<td>{code_spans(c, wrap=True) if '`' in c else breakable(c)}</td>" for c in cells)
    page = (f"<!doctype html><html><head><meta charset='utf-8'><style>{CSS}</style></head><body>"
            f"<table><tr>{'<th>column</th>' * len(cells)}</tr><tr>{row}</tr></table>"
            "<script>var t=document.querySelector('table');document.title='W'+document.documentElement.scrollWidth"
            "+'T'+t.scrollWidth+'C'+t.clientWidth;</script></body></html>")
    path = tmp_path / "page.html"
    path.write_text(page)
    chromium = _chromium()
    assert chromium is not None
    dom = subprocess.run([chromium, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
                          "--window-size=1280,900", "--dump-dom", path.as_uri()],
                         capture_output=True, text=True, timeout=60, check=False).stdout
    found = re.search(r"<title>W(\d+)T(\d+)C(\d+)</title>", dom)
    if found is None:
        pytest.skip("headless Chromium did not render the page here")
    page_width, table_width, table_box = (int(g) for g in found.groups())
    assert page_width <= 1280
    assert table_width <= table_box


def test_a_log_without_evidence_draws_no_empty_error_plots(realdata: Path, tmp_path: Path) -> None:
    """aruco_images.bag: seven markers in one image, nothing to measure the chain against. The report says so
    instead of "against the none: median n/a" over two empty plots, and keeps the world points and the image."""
    from framechain.pipeline import run
    from framechain.sinks.report import render_report

    bag = realdata / ARUCO_IMAGES_BAG
    chain = tmp_path / "chain.yaml"
    chain.write_text("frames: {camera: raspicam, body: base_link, world: map}\n"
                     "topics: {image: /raspicam_node/image/compressed}\n"
                     "evidence: {markers: {dictionary: DICT_5X5_1000, size_m: 0.14}}\n"
                     "mounts:\n"
                     "  - {parent: map, child: base_link, xyz: [0, 0, 0], rpy: [0, 0, 0]}\n"
                     "  - {parent: base_link, child: raspicam, xyz: [0.1, 0, 0.3], rpy: [-1.5707963, 0, -1.5707963]}\n")
    made = run(bag, chain)
    assert made.attributed().metric == "none"
    paths = render_report(made, tmp_path / "report")
    page, text = paths["html"].read_text(), paths["md"].read_text()
    for written in (page, text):
        assert "No error measured: the log has no evidence to measure the chain against." in written
        assert "Against the none" not in written
    assert not (tmp_path / "report" / "error_per_hop.png").exists()
    assert not (tmp_path / "report" / "error_vs_speed.png").exists()
    assert (tmp_path / "report" / "world_top_down.png").exists()
    assert "What the camera saw" in page
