"""Packages and the optional C helper; the metadata is in pyproject.toml.

`optional=True`: without a compiler or the Python headers the build skips the
extension and installs the pure-Python package, which gives the same results,
slower. The repository's decoders/ folder ships inside the wheel as
cananalyze/_decoders (network/profile.py looks there first, then in the checkout).
"""

from setuptools import Extension, find_packages, setup

setup(
    packages=find_packages(include=["cananalyze", "cananalyze.*"]) + ["cananalyze._decoders"],
    package_dir={"cananalyze._decoders": "decoders"},
    package_data={"cananalyze._decoders": ["*.eds", "*.dcf", "*.toml"]},
    ext_modules=[
        Extension(
            "cananalyze.runtime._speedups",
            sources=["cananalyze/runtime/_speedups.c"],
            extra_compile_args=["-O2", "-ffp-contract=off"],
            optional=True,
        )
    ],
)
