"""The job's stages and what they produce, without bpy: jobs.py (the compositions: radiosity,
solve, reduce, a Live stroke), checks.py and meshing.py (before any work), model.py (stage 1, the
problem), stages.py (stages 2-4), notes.py (the warnings' texts and the sidebar's lines), report.py (the
JSON report), stored.py (the result kept in a .blend), polygons.py (patches -> the artist's
polygons), viewing.py (the normal-view radiance) and chart.py (the error chart's pixels)."""
