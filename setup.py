"""The one thing pyproject.toml cannot say: the repository's top-level folders install as subpackages of `eyehil`.

emulator/ -> eyehil.emulator, drivers/ -> eyehil.drivers, protocols/ -> eyehil.protocols, analysis/ ->
eyehil.analysis, eyehil/ -> eyehil; every package below them is found, so a new folder needs no edit here.
"""

from setuptools import find_packages, setup

ROOTS = ("emulator", "drivers", "protocols", "analysis")

setup(
    packages=["eyehil"] + [f"eyehil.{root}{'.' + sub if sub else ''}" for root in ROOTS
                           for sub in ["", *find_packages(root)]],
    package_dir={"eyehil": "eyehil", **{f"eyehil.{root}": root for root in ROOTS}},
)
