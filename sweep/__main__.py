"""``python -m nematic_solids.sweep ...`` is the ``nematic`` program."""

from .cli import app

app(prog_name="nematic")
