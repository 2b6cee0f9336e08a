"""Shapes from files: CAD solids (STEP, IGES, BREP through gmsh) and closed triangulated surfaces
(STL, OBJ, PLY through trimesh) turned into the boundary map of a ``meshgen.geometry.plugins.Geometry``."""

__all__: list[str] = []
