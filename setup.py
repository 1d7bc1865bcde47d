"""Packages and the optional C helper; the metadata is in pyproject.toml.

`optional=True`: without a compiler or the Python headers the build skips the
extension and installs the pure-Python package, which gives the same results,
slower. `_BuildExt` says so in one line instead of setuptools' quiet warning;
`cananalyze --version` tells an installed copy which path it takes. The
repository's decoders/ folder ships inside the wheel as cananalyze/_decoders
(devices/profile.py looks there first, then in the checkout).
"""

import sys

from setuptools import Extension, find_packages, setup
from setuptools.command.build_ext import build_ext

NOT_BUILT = "cananalyze: C helper not built (no compiler?): using the pure-Python path, same results, slower"


class _BuildExt(build_ext):
    """build_ext that reports an optional extension it could not build, in one line."""

    def build_extension(self, ext: Extension) -> None:
        try:
            super().build_extension(ext)
        except Exception as exc:  # CompileError, LinkError, a missing compiler: any of them
            if not ext.optional:
                raise
            print(f"{NOT_BUILT} ({type(exc).__name__})", file=sys.stderr, flush=True)


setup(
    cmdclass={"build_ext": _BuildExt},
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
