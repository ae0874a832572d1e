"""The ``nematic`` program (typer; also ``python -m nematic_solids.sweep``): parses the command
line, calls :mod:`nematic_solids.sweep` and prints.

Exit codes: 0 success; 1 some runs failed (they are listed); 2 bad input (invalid campaign,
unreachable scheduler) or refused to start (the campaign is locked by another driver);
3 stopped early because more runs failed than ``nematic run --max-failures`` allows;
130 interrupted (Ctrl-C / SIGTERM; rerun the same command to resume).

:data:`COMMANDS` is every command, in the order ``nematic --help`` lists them; each is a
plain function in its group's module, registered on :data:`~nematic_solids.sweep.cli.app.app` here.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from . import (
    campaigns,
    catalogue,
    driver,
    export,
    figures,
    report,
    run,
    service,
    simulate,
    stability,
    status,
    verify,
)
from .app import RegistryHelpCommand, app

COMMANDS: dict[str, Callable[..., Any]] = {
    "validate": campaigns.validate,
    "run": run.run,
    "status": status.status,
    "aggregate": campaigns.aggregate,
    "verify": verify.verify,
    "stop": driver.stop,
    "serve": service.serve,
    "submit": service.submit,
    "queue": service.queue,
    "cancel": service.cancel,
    "export": export.export,
    "report": report.report,
    "simulate": simulate.simulate,
    "stability": stability.stability,
    "figures": figures.figures,
    "catalogue": catalogue.catalogue,
}

#: the commands whose help names the registered figures and fits
NAMING_REGISTRIES = {"figures"}

for _name, _command in COMMANDS.items():
    app.command(_name, cls=RegistryHelpCommand if _name in NAMING_REGISTRIES else None)(_command)

__all__ = ["COMMANDS", "app"]
