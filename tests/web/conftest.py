"""The browser tests' Chromium (Debian's package, installed when missing)."""

from __future__ import annotations

import os
import shutil
import subprocess

import pytest

from browser_helpers import CHROMIUM


@pytest.fixture(scope="session")
def chromium() -> str:
    """Debian's chromium, installed with apt-get when missing (CI runs as root on a fresh machine)."""
    if not os.path.exists(CHROMIUM):
        problem = "apt-get is not available"
        if shutil.which("apt-get") and hasattr(os, "geteuid") and os.geteuid() == 0:
            env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
            problem = ""
            # test files on other xdist workers may install at the same moment: wait for dpkg's lock
            wait = ["-o", "DPkg::Lock::Timeout=600"]
            for cmd in (["apt-get", *wait, "update"], ["apt-get", *wait, "install", "-y", "--no-install-recommends", "chromium"]):
                result = subprocess.run(cmd, capture_output=True, text=True, timeout=900, env=env)
                if result.returncode != 0:
                    problem = f"{' '.join(cmd)} failed: {result.stderr.strip()[-500:]}"
                    break
        elif shutil.which("apt-get"):
            problem = "installing needs root"
        if not os.path.exists(CHROMIUM):
            pytest.skip(f"cannot install Debian's chromium ({problem}); the browser test needs {CHROMIUM}")
    return CHROMIUM
