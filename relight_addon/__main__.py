"""``python -m relight_addon ...`` and ``blender -b --python relight_addon/__main__.py -- ...``.

Both run ``cli.main`` (see README.md). Run as a plain script (Blender's ``--python``), this
file imports its own package from its parent folder by the folder's name.
"""
import sys

import os

if __package__:
    from . import cli as _cli
else:  # blender -b --python path/to/relight_addon/__main__.py -- radiosity ...
    import importlib

    _here = os.path.dirname(os.path.abspath(__file__))
    sys.path.insert(0, os.path.dirname(_here))
    _cli = importlib.import_module(os.path.basename(_here) + ".cli")
main, script_argv = _cli.main, _cli.script_argv

if __name__ == "__main__":
    code = main(script_argv(sys.argv))
    if _cli.abandoned_jobs():  # a cancelled job: no interpreter shutdown under (or after) it
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except Exception:
                pass
        os._exit(code)
    sys.exit(code)
