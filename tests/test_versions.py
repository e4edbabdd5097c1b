"""One release number: avp_common.version, every package.xml and setup.py, the newest CHANGELOG release, `avp
--version`."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

from avp_common.version import __version__

ROOT = Path(__file__).resolve().parents[1]


def test_packages_and_changelog_carry_the_release():
    assert re.fullmatch(r"\d+\.\d+\.\d+", __version__)
    xml = {p.parent.name: re.search(r"<version>([^<]+)</version>", p.read_text()).group(1)
           for p in (ROOT / "src").glob("*/package.xml")}
    setup = {p.parent.name: re.search(r'version="([^"]+)"', p.read_text()).group(1)
             for p in (ROOT / "src").glob("*/setup.py")}
    assert xml and set(xml.values()) == {__version__}, xml
    assert setup and set(setup.values()) == {__version__}, setup
    releases = re.findall(r"^## \[(\d+\.\d+\.\d+)\] - (\d{4}-\d{2}-\d{2})$", (ROOT / "CHANGELOG.md").read_text(), re.M)
    assert releases and releases[0][0] == __version__, releases[:2]


def test_avp_version():
    r = subprocess.run([sys.executable, "-m", "avp_bringup.cli", "--version"], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0 and r.stdout.strip() == f"avp {__version__}", (r.stdout, r.stderr)
