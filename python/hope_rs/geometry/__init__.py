"""Geometry: meshes and their files, position-fixed numbering, orientation, grid sites, map files."""
