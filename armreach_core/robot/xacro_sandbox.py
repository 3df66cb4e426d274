"""xacro files processed without ROS, and without trusting them.

A ``.xacro`` file (or any file whose text holds xacro markup: ``xmlns:xacro``, ``<xacro:...>``,
``${...}``, ``$(find ...)``) is expanded to URDF text by the ``xacro`` package from PyPI (the
one ROS uses, maintained by the ROS community), with the user's arguments (``xacro_args``).

A description downloaded from anywhere is data, not a program, so the expansion is confined:

* **files**: xacro reads only files inside the description's folder, its own package and
  the packages the user named (``package_dirs``) or put on ``ROS_PACKAGE_PATH``
  (:meth:`~armreach_core.robot.packages.Packages.roots`), each at most
  :data:`MAX_FILE_BYTES` and with no DTD; ``$(find NAME)`` is answered by
  :class:`~armreach_core.robot.packages.Packages`, never by a ROS installation;
* **code**: expressions (``${...}``, ``$(eval ...)``) are evaluated with no Python built-ins
  but xacro's own list, and an expression naming anything private (``_x``, ``__class__``)
  or a reflective built-in (``vars``, ``type``, ``getattr``...) is refused: those are the
  ways out of a restricted ``eval``;
* **older syntax**: the elements ROS 1's xacro took without the ``xacro:`` prefix
  (``<property>``, ``<macro>``... :data:`LEGACY_TAGS`) are read as xacro's, as ROS 1 did;
* **environment**: ``$(env NAME)`` and ``$(optenv NAME)`` are refused unless the user allows
  them (``allow_xacro_env=True``, ``--allow-xacro-env``).

Whatever breaks a rule is a :class:`~armreach_core.errors.URDFError` naming the rule and the
fix. xacro keeps its state in module globals, so one file is processed at a time (a lock).
"""

from __future__ import annotations

import contextlib
import io
import logging
import math
import re
import threading
import warnings
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from types import CodeType
from typing import Any

from armreach_core.errors import URDFError
from armreach_core.robot.packages import ROS_PACKAGE_PATH, Packages

log = logging.getLogger("armreach.xacro")

#: Largest file a xacro may read, in bytes.
MAX_FILE_BYTES = 16 * 1024 * 1024
#: Names an expression may not use: the ways out of a restricted ``eval``.
FORBIDDEN_NAMES = frozenset(
    {"vars", "type", "getattr", "setattr", "delattr", "globals", "locals", "eval", "exec", "compile", "open",
     "mro", "breakpoint", "input", "help", "memoryview", "object", "super", "classmethod", "staticmethod"}
)  # fmt: skip
#: Prefixes of attribute names of frames, generators and tracebacks (a frame's globals are a way out).
FORBIDDEN_PREFIXES = ("_", "f_", "gi_", "cr_", "ag_", "tb_", "co_", "func_")

_MARKUP = re.compile(rb"xmlns:xacro|<xacro:|\$\{|\$\((?:find|arg|eval|env|optenv|dirname)\b")
_DTD = re.compile(rb"<!\s*(DOCTYPE|ENTITY)", re.IGNORECASE)
_LOCK = threading.Lock()
#: xacro elements that ROS 1's xacro also took without the ``xacro:`` prefix (older descriptions use them so).
LEGACY_TAGS = ("property", "macro", "insert_block", "include", "if", "unless", "arg")
_LEGACY = re.compile(r"<(/?)(" + "|".join(LEGACY_TAGS) + r")(?=[\s/>])")


def is_xacro(path: Path, data: bytes) -> bool:
    """Whether the file at ``path`` with content ``data`` is xacro (by its suffix or its markup)."""
    return path.suffix.lower() == ".xacro" or _MARKUP.search(data) is not None


class _Refused(Exception):
    """A rule of the sandbox was broken (kept, and raised as a URDFError once xacro stops)."""


def check_expression(code: CodeType, text: str) -> None:
    """Refuse a compiled expression that names anything private or reflective (see the module docstring)."""
    for name in code.co_names:
        if name in FORBIDDEN_NAMES or name.startswith(FORBIDDEN_PREFIXES):
            raise _Refused(
                f"the expression {text.strip()!r} uses {name!r}, which armreach does not let a xacro use (it is "
                "a way to run code beyond xacro's expressions); compute the value another way, or process the "
                "file with xacro yourself if you trust it and pass the URDF"
            )
    for const in code.co_consts:
        if isinstance(const, CodeType):
            check_expression(const, text)
        elif isinstance(const, str) and "__" in const:
            raise _Refused(
                f"the expression {text.strip()!r} holds a double underscore, which armreach does not let a xacro "
                "use (a way to reach Python's internals); remove it"
            )


class _Sandbox:
    """The replacements xacro calls while a file is processed, and what they refused."""

    def __init__(self, packages: Packages, allow_env: bool) -> None:
        self.packages = packages
        self.allow_env = allow_env
        self.roots = packages.roots()
        self.refused: list[str] = []

    def refuse(self, message: str) -> _Refused:
        self.refused.append(message)
        return _Refused(message)

    def open(self, file: Any, mode: str = "r", *args: Any, **kwargs: Any) -> io.StringIO:
        path = Path(str(file)).expanduser()
        if any(flag in mode for flag in "wax+"):
            raise self.refuse(f"the xacro tried to write {str(path)!r}; a description never writes files")
        try:
            real = path.resolve()
        except (OSError, ValueError) as exc:
            raise self.refuse(f"the xacro names {str(path)!r}, which cannot be looked up ({exc})") from None
        if not any(real == root or real.is_relative_to(root) for root in self.roots):
            raise self.refuse(
                f"the xacro reads {str(real)!r}, outside the description's folder and packages "
                f"({', '.join(str(r) for r in self.roots)}); armreach reads only those: if that file belongs to "
                "a package you trust, name it with package_dirs={NAME: PATH} (--package-dir NAME=PATH)"
            )
        if not real.is_file():
            raise FileNotFoundError(2, "No such file", str(real))
        if real.stat().st_size > MAX_FILE_BYTES:
            raise self.refuse(f"the xacro reads {str(real)!r}, over {MAX_FILE_BYTES} bytes: no description is")
        data = real.read_bytes()
        if _DTD.search(data):
            raise self.refuse(f"{str(real)!r} declares a DTD or XML entities, which armreach never reads; remove them")
        text = data.decode("utf-8")
        if _LEGACY.search(text):  # no URDF element has these names: ROS 1 read them as xacro's
            log.info("%s uses xacro elements without the xacro: prefix (ROS 1 style); read as xacro's", real)
            text = _LEGACY.sub(r"<\1xacro:\2", text)
        return io.StringIO(text)

    def find(self, name: str) -> str:
        folder = self.packages.find(name)
        if folder is not None:
            self.roots.append(folder)  # a package the description names by the rules is readable
        else:
            raise self.refuse(
                f"$(find {name}): no package {name!r} is known (known: {', '.join(self.packages.known()) or 'none'}); "
                f"say where it is with package_dirs={{{name!r}: PATH}} (--package-dir {name}=PATH) "
                f"or {ROS_PACKAGE_PATH}"
            )
        return str(folder)

    def env(self, original: Callable[..., str]) -> Callable[..., str]:
        def read(name: str, *default: str, **named: str) -> str:
            if not self.allow_env:
                raise self.refuse(
                    f"the xacro reads the environment variable {name!r} ($(env)/$(optenv)), which armreach does not "
                    "let a description do unless asked: pass the value as a xacro argument, or allow it with "
                    "allow_xacro_env=True (--allow-xacro-env) if you trust this file"
                )
            return original(name, *default, **named)

        return read

    def safe_eval(self, expr: str, globals: dict[str, Any], locals: Any = None) -> Any:
        try:
            code = compile(expr.strip(), "<expression>", "eval")
        except SyntaxError as exc:
            raise self.refuse(f"the expression {expr.strip()!r} is not a valid expression ({exc.msg})") from None
        try:
            check_expression(code, expr)
        except _Refused as exc:
            raise self.refuse(str(exc)) from None
        globals.update(__builtins__={})
        return eval(code, globals, locals)  # checked above, and no built-ins

    def substitution_eval(self, text: str, context: dict[str, Any]) -> str:
        """``$(eval ...)`` with xacro's math and substitution functions, and no built-ins."""
        from xacro import substitution_args

        args = context.get("arg", {})
        functions: dict[str, Any] = {k: v for k, v in math.__dict__.items() if not k.startswith("_")}
        functions.update(
            arg=lambda name: substitution_args.convert_value(substitution_args._eval_arg(name, args=args), "auto"),
            dirname=lambda: substitution_args._eval_dirname(context.get("filename")),
            find=self.find,
            env=self.env(substitution_args._eval_env),
            optenv=self.env(substitution_args._eval_optenv),
        )
        scope = {**functions, **{k: substitution_args.convert_value(v, "auto") for k, v in args.items()}}
        return str(self.safe_eval(text, {}, scope))


@contextlib.contextmanager
def _patched(sandbox: _Sandbox) -> Iterator[None]:
    import xacro
    from xacro import substitution_args

    saved_xacro = {name: getattr(xacro, name, None) for name in ("safe_eval", "open")}
    names = ("_eval_find", "_eval_env", "_eval_optenv", "_eval")
    saved_args = {name: getattr(substitution_args, name) for name in names}
    xacro.safe_eval = sandbox.safe_eval
    xacro.open = sandbox.open
    substitution_args._eval_find = sandbox.find
    substitution_args._eval_env = sandbox.env(saved_args["_eval_env"])
    substitution_args._eval_optenv = sandbox.env(saved_args["_eval_optenv"])
    substitution_args._eval = sandbox.substitution_eval
    try:
        yield
    finally:
        for name, value in saved_args.items():
            setattr(substitution_args, name, value)
        xacro.safe_eval = saved_xacro["safe_eval"]
        del xacro.open


def process_xacro(path: Path, args: Mapping[str, str], packages: Packages, *, allow_env: bool = False) -> bytes:
    """The URDF text a xacro file expands to, under the rules of the module docstring.

    Raises:
        URDFError: the ``xacro`` package is missing, the file breaks a rule of the sandbox,
            or xacro cannot process it (its message, and the file).
    """
    try:
        with warnings.catch_warnings():  # on Python 3.10 its enum of units warns about a private name
            warnings.simplefilter("ignore", DeprecationWarning)
            import xacro
    except ImportError:
        raise URDFError(
            f"{str(path)!r} is a xacro file (it holds xacro markup), and the xacro package that expands it is not "
            "installed: pip install xacro (or run xacro yourself and pass the .urdf it writes)"
        ) from None
    sandbox = _Sandbox(packages, allow_env)
    messages = io.StringIO()
    with _LOCK, _patched(sandbox), contextlib.redirect_stderr(messages):
        try:
            document = xacro.process_file(str(path), mappings={str(k): str(v) for k, v in args.items()})
            text = str(document.toprettyxml(indent="  "))
            failure = None
        except Exception as exc:  # xacro wraps what it calls into its own exceptions
            failure = " ".join(str(exc).split()) or type(exc).__name__
    if messages.getvalue().strip():
        log.info("xacro on %s: %s", path, " ".join(messages.getvalue().split()))
    if sandbox.refused:
        raise URDFError(f"xacro file {str(path)!r} was refused: {sandbox.refused[0]}")
    if failure is not None:
        raise URDFError(f"xacro could not process {str(path)!r}: {failure}; {_fix(failure)}")
    return text.encode("utf-8")


def _fix(failure: str) -> str:
    """What to do about xacro's ``failure``: a name used in ``${...}`` and never defined is a
    property missing from the file, which no argument supplies (arguments are ``$(arg NAME)``)."""
    undefined = re.search(r"name '(\w+)' is not defined", failure)
    if undefined is None:
        return (
            "fix the file, or give the arguments it needs with xacro_args={NAME: VALUE} (--xacro-arg NAME:=VALUE) "
            "and the packages with package_dirs (--package-dir)"
        )
    name = undefined.group(1)
    return (
        f"the file's ${{...}} expressions use {name!r}, a property it never defines and no xacro argument "
        f"gives (an argument is read as $(arg {name})): define it in the file, "
        f'<xacro:property name="{name}" value="..."/>, or, if it is meant as an argument, write $(arg {name}) '
        f"there and give xacro_args={{{name!r}: VALUE}} (--xacro-arg {name}:=VALUE)"
    )
