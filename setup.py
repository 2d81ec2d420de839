"""Build step of the wheel: the metadata is in pyproject.toml; this only adds the knowledge and the
numbers. ``rules/`` and ``models/`` are top-level folders (a user edits them, not the code), which
a wheel cannot hold, so the build copies them into the package as ``semmap_pp/_share/``, where
``semmap_pp.resources`` finds them once installed. An editable install reads the checkout's own
folders and gets no copy."""

import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

HERE = Path(__file__).resolve().parent
SHIPPED = ("rules", "models")    # semmap_pp.resources.SHIPPED


class BuildPyWithShare(build_py):
    def run(self):
        super().run()
        if getattr(self, "editable_mode", False):
            return
        for name in SHIPPED:
            shutil.copytree(HERE / name, Path(self.build_lib) / "semmap_pp" / "_share" / name,
                            dirs_exist_ok=True,
                            ignore=shutil.ignore_patterns("__pycache__", "*.pyc", ".*"))


setup(cmdclass={"build_py": BuildPyWithShare})
