"""A griffe extension: the repository's `fitting/` folder installs as `jaxskin.fitting`
(pyproject's package-dir), which griffe's static finder cannot see; this loads it from the
repository and mounts it under `jaxskin`, so the reference pages name it as users import it."""

from __future__ import annotations

import griffe


class MountFitting(griffe.Extension):
    def on_package(self, *, pkg: griffe.Module, loader: griffe.GriffeLoader, **kwargs) -> None:
        if pkg.name == "jaxskin" and "fitting" not in pkg.members:
            fitting = loader.load("fitting", try_relative_path=False)
            pkg.set_member("fitting", fitting)
