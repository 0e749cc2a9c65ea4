"""Python tools for sdfmesh: plots and the report of `toolkit compare` results.

Modules:
  data       reading the compare and scaling CSVs (schema version 1)
  offscreen  picking a VTK render window that works without a display (EGL or OSMesa)
  plots      2D plots (matplotlib) and 3D views (pyvista, off screen)
  stats      bootstrap confidence intervals and the Mann-Whitney U test
  report     REPORT.md with every plot, the tables, the hypothesis test and the answer
"""
