"""The files jaxskin reads at run time: meshes, scenes, spectra, materials, examples.

Installed as `jaxskin.data` (see `pyproject.toml`); read through `jaxskin.io.data_dir()`.
The `make_*.py` scripts beside this file remake some of them (see README.md here).
"""
