"""A run of meshgen, from request to published files, and what guards it.

- ``request``: ``MeshRequest`` and ``carry_out``, the one path from a request to a mesh;
  ``meshing``: the ``Mesh`` it returns and the mesh of a block set (one block or several);
- ``chunked``: meshes larger than memory, on Dask (``scheduler``: where the blocks run);
- ``publish`` and ``atomic``: every output written under a temporary name, then renamed;
- ``limits``, ``resources``: sizes checked before allocation against what the machine has;
- ``inputs``, ``trust``: input files opened defensively, and what a file may name;
- ``signals``: SIGTERM and SIGHUP unwind like Ctrl-C.
"""

__all__: list[str] = []  # a namespace package: import the submodules
