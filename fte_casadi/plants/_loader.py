"""Resolve a plant specification: a built-in name, ``path/to/file.py:function`` or ``package.module:function``."""

from __future__ import annotations

import contextlib
import importlib
import importlib.util
import sys
import traceback
from collections.abc import Iterator
from pathlib import Path

from ..errors import FteError, PlantError, PlantLoadError
from ..model import Plant

__all__ = []  # public: docs/api.md


def builtin_names() -> list[str]:
    from ._builtin import BUILTIN

    return sorted(BUILTIN)


@contextlib.contextmanager
def _plant_folder(path: str | None) -> Iterator[None]:
    """The plant file's folder importable while its code runs, as for a script run from there.

    A plant file may import modules beside it (parameters apart from equations). The folder goes
    first on ``sys.path`` only while the file is executed and its functions run; afterwards
    ``sys.path`` is as it was and the modules imported from that folder are taken out of
    ``sys.modules`` (the plant module keeps its own references), so that another plant folder
    with a helper of the same name gets its own.
    """
    if path is None:
        yield
        return
    folder = str(Path(path).resolve().parent)
    before = set(sys.modules)
    sys.path.insert(0, folder)
    try:
        yield
    finally:
        with contextlib.suppress(ValueError):
            sys.path.remove(folder)
        for name in set(sys.modules) - before:
            origin = getattr(sys.modules[name], "__file__", None)
            if origin and Path(origin).resolve().is_relative_to(folder):
                del sys.modules[name]


def _last_frame(exc: BaseException, path: str | None) -> str:
    tb = traceback.extract_tb(exc.__traceback__)
    frames = [f for f in tb if path is None or Path(f.filename).resolve() == Path(path).resolve()]
    f = (frames or tb)[-1] if (frames or tb) else None
    return f" (at {f.filename}:{f.lineno})" if f else ""


def load_plant(spec: str) -> Plant:
    """Return the :class:`Plant` named by ``spec``; every failure is a :class:`PlantLoadError`."""
    from ._builtin import BUILTIN

    if not isinstance(spec, str) or not spec.strip():
        raise PlantLoadError(
            "no plant given: name a built-in plant (manipulator, three-tank, quadruple-tank) or FILE.py:FUNCTION"
        )
    spec = spec.strip()
    if spec in BUILTIN:
        return BUILTIN[spec]()
    if ":" not in spec:
        hint = (
            " (a file needs ':function' after it, e.g. my_plant.py:make_plant)"
            if spec.endswith(".py")
            else ""
        )
        raise PlantLoadError(
            f"unknown plant {spec!r}{hint}: use a built-in name ({', '.join(builtin_names())}), "
            "path/to/file.py:function or package.module:function"
        )
    target, func = spec.rsplit(":", 1)
    if not func.isidentifier():
        raise PlantLoadError(f"{func!r} in {spec!r} is not a function name; write FILE.py:FUNCTION")
    path = None
    if target.endswith(".py") or "/" in target or "\\" in target:
        p = Path(target)
        if not p.is_file():
            raise PlantLoadError(
                f"plant file {target!r} does not exist; check the path (relative to {Path.cwd()})"
            )
        path = str(p)
        name = f"fte_user_plant_{abs(hash(str(p.resolve())))}"
        try:
            source = p.read_text()
            compile(source, str(p), "exec")
        except SyntaxError as exc:
            raise PlantLoadError(
                f"plant file {target!r} has a syntax error at line {exc.lineno}: {exc.msg}; fix the file"
            ) from None
        except (OSError, UnicodeDecodeError) as exc:
            raise PlantLoadError(f"plant file {target!r} cannot be read: {exc}") from None
        mspec = importlib.util.spec_from_file_location(name, p)
        module = importlib.util.module_from_spec(mspec)
        sys.modules[name] = module  # before executing it: dataclasses in the file look it up
        try:
            with _plant_folder(path):
                mspec.loader.exec_module(module)
        except Exception as exc:  # noqa: BLE001 - user code may raise anything; report it
            sys.modules.pop(name, None)
            raise PlantLoadError(
                f"importing plant file {target!r} raised {type(exc).__name__}: {exc}{_last_frame(exc, path)}; fix the file"
            ) from None
    else:
        try:
            module = importlib.import_module(target)
        except ImportError as exc:
            raise PlantLoadError(
                f"cannot import module {target!r}: {exc}; is it installed or on PYTHONPATH?"
            ) from None
        except Exception as exc:  # noqa: BLE001
            raise PlantLoadError(f"importing module {target!r} raised {type(exc).__name__}: {exc}") from None
    fn = getattr(module, func, None)
    if fn is None or not callable(fn):
        avail = [k for k, v in vars(module).items() if callable(v) and not k.startswith("_")]
        shown = ", ".join(avail[:10]) + (f" and {len(avail) - 10} more" if len(avail) > 10 else "")
        raise PlantLoadError(f"{target!r} has no function {func!r}; callables there: {shown or 'none'}")
    try:
        with _plant_folder(path):
            plant = fn()
    except FteError as exc:
        raise PlantError(f"plant function {spec!r} failed: {exc}") from None
    except Exception as exc:  # noqa: BLE001
        raise PlantLoadError(
            f"plant function {spec!r} raised {type(exc).__name__}: {exc}{_last_frame(exc, path)}; fix the plant definition"
        ) from None
    if not isinstance(plant, Plant):
        raise PlantLoadError(
            f"plant function {spec!r} returned {type(plant).__name__}, not a Plant: end it with `return builder.build()`"
        )
    return plant


def load_scenario(spec: str):
    """The experiment that goes with a plant spec.

    Built-in plants: the paper's scenario. ``file.py:function`` / ``module:function``: the
    module's ``function_scenario()`` or else its ``scenario()``.
    """
    from ._builtin import SCENARIOS

    spec = spec.strip()
    if spec in SCENARIOS:
        return SCENARIOS[spec]()
    if ":" not in spec:
        raise PlantLoadError(f"unknown plant {spec!r}: no scenario for it")
    target, func = spec.rsplit(":", 1)
    path = None
    # the plant module was imported by load_plant; import it again the same way
    if target.endswith(".py") or "/" in target or "\\" in target:
        path = target
        name = f"fte_user_plant_{abs(hash(str(Path(target).resolve())))}"
        module = sys.modules.get(name)
        if module is None:
            load_plant(spec)
            module = sys.modules[name]
    else:
        module = importlib.import_module(target)
    for attr in (f"{func}_scenario", "scenario"):
        fn = getattr(module, attr, None)
        if callable(fn):
            try:
                with _plant_folder(path):
                    return fn()
            except FteError:
                raise
            except Exception as exc:  # noqa: BLE001
                raise PlantLoadError(f"{target}:{attr}() raised {type(exc).__name__}: {exc}") from None
    raise PlantLoadError(
        f"{target!r} defines no scenario for {func!r}: add a function `scenario()` (or `{func}_scenario()`) "
        "beside the plant that returns fte_casadi.sim.Scenario(...) with its faults, horizon and time step (examples/pendulum_plain.py "
        "in the fte_casadi repository has one to copy)"
    )
