"""The ``fte`` command: the only place that prints or exits.

Every command turns the library's errors into a one-paragraph message and exit status 2
(bad input) or 1 (a failed design/run); ``--debug`` shows the Python traceback instead.

One module per command (``_simulate.py`` holds ``fte sweep`` too); what several of them share is in
``_common.py`` (the error guard, the Ctrl-C report, argument checks) and ``_targets.py`` (the design or
plant a command works on). A new command is a module with a ``click.command`` and one
``add_command`` line below.
"""

from __future__ import annotations

import click

from .. import _interrupt
from . import _bench as bench
from . import _codegen as codegen
from . import _derive as derive
from . import _design as design
from . import _reproduce as reproduce
from . import _simulate as simulate
from . import _tune as tune
from ._common import EXIT_BAD_INPUT as EXIT_BAD_INPUT
from ._common import EXIT_FAILED as EXIT_FAILED
from ._common import _fail, _interrupted


class _Fte(click.Group):
    """The ``fte`` group: a Ctrl-C always ends a command with status 130, nothing written after it
    (:mod:`fte_casadi._interrupt`), whatever catches the ``KeyboardInterrupt`` it raises."""

    def main(self, *args, **kwargs):
        with _interrupt.handling():
            try:
                return super().main(*args, **kwargs)
            except SystemExit as exc:
                if _interrupt.pending() and exc.code != 130:  # a Ctrl-C that something swallowed
                    raise SystemExit(130) from None
                raise

    def invoke(self, ctx):
        try:
            rv = super().invoke(ctx)
        except KeyboardInterrupt:  # outside a command's guard (click's own "Aborted!" would exit 1)
            _fail(_interrupted(), 130)
        if _interrupt.pending():
            _fail(_interrupted(), 130)
        return rv


@click.group(cls=_Fte, context_settings={"help_option_names": ["-h", "--help"]})
@click.option("--debug", is_flag=True, help="Show Python tracebacks on errors.")
@click.version_option(package_name="fte_casadi")
def main(debug: bool) -> None:
    """fte: certified fault estimation and fault-tolerant control, from CasADi equations to embedded C.

    PLANT is a built-in name (manipulator, three-tank, quadruple-tank), path/to/file.py:function or
    package.module:function returning a Plant.
    """


for command in (
    derive.derive, design.design, codegen.codegen, simulate.simulate, simulate.sweep, reproduce.reproduce,
    bench.bench, tune.tune,
):  # fmt: skip
    main.add_command(command)
