"""``python -m compare``: the ``compare`` command, for when another ``compare`` comes first on the PATH.

ImageMagick installs a ``compare`` of its own (``/usr/bin/compare``); outside the
virtual environment it answers instead of this one. ``python -m compare`` always
runs this package's command, with the same options and exit codes.
"""

from compare.cli import main

if __name__ == "__main__":
    main(prog_name="compare")
