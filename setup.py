"""Packaging beyond pyproject.toml: the built-in scenes ship inside the package.

The built-in scenes, their demonstration scripts and meshes live in ``scenes/`` at the top of the
repository; a wheel carries them as ``dlovr/_scenes/`` (the package ``dlovr._scenes`` mapped onto
that folder), where :func:`dlovr.scene.scenes_dir` finds them in an installed package. An editable
install or a checkout uses ``scenes/`` itself. ``scenes/make_meshes.py`` (the tool that generates the
meshes) is not shipped.
"""

from setuptools import find_packages, setup
from setuptools.command.build_py import build_py

SCENES = "dlovr._scenes"


class BuildPy(build_py):
    """``build_py`` that ships the scene files of ``dlovr._scenes`` but none of its Python modules."""

    def find_package_modules(self, package, package_dir):
        return [] if package == SCENES else super().find_package_modules(package, package_dir)


setup(
    packages=[*find_packages(include=["dlovr", "dlovr.*"]), SCENES],
    package_dir={SCENES: "scenes"},
    package_data={"dlovr": ["data/*", "data/**/*"], SCENES: ["*.toml", "meshes/*.obj"]},
    cmdclass={"build_py": BuildPy},
)
