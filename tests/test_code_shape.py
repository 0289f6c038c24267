"""Functions a newcomer can read: at most about 80 lines of code (the docstring aside) and 12 parameters, or a
docstring that says why.

A function over either limit carries a paragraph beginning "Why so long:" or "Why so many parameters:" in
its docstring.  The functions in ``WAITING`` are over a limit and not yet split or explained; the list may
only shrink: a new function over a limit fails, and so does a listed one that no longer needs its entry.
"""

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "parsim"
MAX_LINES, MAX_PARAMETERS = 80, 12
REASONS = {"lines": "Why so long:", "parameters": "Why so many parameters:"}

WAITING: dict[str, set] = {}


def _overlong(package: Path = PACKAGE) -> dict[str, set]:
    """``{"module:function": {"lines", "parameters"}}`` for each function over a limit without its reason."""
    found = {}
    for path in sorted(package.rglob("*.py")):
        module = path.relative_to(package.parent).as_posix()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            arguments = node.args
            body = node.body[1:] if ast.get_docstring(node) is not None else node.body
            lines = node.end_lineno - body[0].lineno + 1 if body else 0  # the code, without the docstring
            over = {"lines": lines > MAX_LINES,
                    "parameters": len(arguments.posonlyargs + arguments.args + arguments.kwonlyargs) > MAX_PARAMETERS}
            docstring = ast.get_docstring(node) or ""
            missing = {limit for limit, exceeded in over.items() if exceeded and REASONS[limit] not in docstring}
            if missing:
                found[f"{module}:{node.name}"] = missing
    return found


def test_every_function_over_a_limit_says_why_or_is_waiting():
    found = _overlong()
    new = {name: limits for name, limits in found.items() if not limits <= WAITING.get(name, set())}
    assert new == {}, f"functions over {MAX_LINES} lines or {MAX_PARAMETERS} parameters, without a reason: {new}"
    done = {name: limits - found.get(name, set()) for name, limits in WAITING.items()
            if limits - found.get(name, set())}
    assert done == {}, f"no longer over a limit, or now explained: take them out of WAITING: {done}"


def test_a_long_function_or_a_long_signature_is_found_unless_its_docstring_says_why(tmp_path):
    package = tmp_path / "parsim"
    package.mkdir()
    body = "".join(f"    x{i} = {i}\n" for i in range(MAX_LINES + 1))
    long_docstring = "Many lines of docstring.\n" * 100
    parameters = ", ".join(f"a{i}" for i in range(MAX_PARAMETERS + 1))
    (package / "planted.py").write_text(
        f'def long():\n    """A docstring does not count."""\n{body}\n\n'
        f'def short():\n    """{long_docstring}"""\n    return 1\n\n\n'
        f'def wide({parameters}):\n    return 1\n\n\n'
        f'def explained({parameters}):\n    """Why so many parameters: planted."""\n    return 1\n', encoding="utf-8")
    assert _overlong(package) == {"parsim/planted.py:long": {"lines"}, "parsim/planted.py:wide": {"parameters"}}
