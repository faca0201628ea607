"""The job's stages and what they produce, without bpy: jobs.py (the stages), report.py (the
JSON report), stored.py (the result kept in a .blend), polygons.py (patches -> the artist's
polygons), viewing.py (the normal-view radiance) and chart.py (the error chart's pixels)."""
