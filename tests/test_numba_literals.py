"""No compiled kernel calls another with an integer or boolean constant, nor leaves one of
its defaulted arguments out (read from the source).

Numba compiles a kernel once per argument type. Called from another kernel with a
constant (`evaluate_into(..., 1, ...)`, `curve_value(p, _FAL, x)`, `_arc(..., True, -1)`),
the argument's type is the literal `Literal[int](1)`, and every distinct constant is one
more compilation of the whole callee; an argument left to its default is typed
`omitted(...)`, another one. Measured on the bench's knee from an empty cache: the
compiled-measure interpreter `evaluate_program` was compiled four times (order 0, 1, 2
and int64), the OpenSim ellipsoid rule twice, `rotation_angle_blocks` and
`curve_value` four times each. Passing `np.int64(1)` or `np.bool_(True)` types them
int64 and bool: one compilation."""

import ast
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src" / "openfdk"


def _is_jit(decorator):
    node = decorator.func if isinstance(decorator, ast.Call) else decorator
    name = node.attr if isinstance(node, ast.Attribute) else getattr(node, "id", "")
    return name in ("njit", "jit")


def _imported(path, tree):
    """{name: (module path, name there)} of the module's ``from .x import name`` and
    ``from openfdk.x import name`` lines."""
    out = {}
    for node in tree.body:
        if isinstance(node, ast.ImportFrom) and (node.level or (node.module or "").startswith("openfdk.")):
            if node.level:
                base = path.parent
                for _ in range(node.level - 1):
                    base = base.parent
                target = base.joinpath(*node.module.split(".")) if node.module else base
            else:
                target = SRC.joinpath(*node.module.split(".")[1:])
            file = target.with_suffix(".py") if target.with_suffix(".py").is_file() else target / "__init__.py"
            for alias in node.names:
                out[alias.asname or alias.name] = (file, alias.name)
    return out


def _kernels():
    """{module path: (tree, {kernel name: FunctionDef}, {module-level int/bool constant
    names}, {imported name: (module path, name)})}"""
    out = {}
    for path in sorted(SRC.rglob("*.py")):
        tree = ast.parse(path.read_text(), str(path))
        kernels = {f.name: f for f in tree.body
                   if isinstance(f, ast.FunctionDef) and any(_is_jit(d) for d in f.decorator_list)}
        out[path] = (tree, kernels, _int_constants(tree), _imported(path, tree))
    for _ in range(2):  # constants defined from other modules' constants (`_FV = _FAL + CURVE_WIDTH`)
        for path, (tree, kernels, constants, imported) in out.items():
            known = {name for name, (file, there) in imported.items() if there in out.get(file, (0, 0, set()))[2]}
            out[path] = (tree, kernels, _int_constants(tree, known), imported)
    return out


def _int_expression(node, constants):
    """True for an expression of int or bool constants and names in ``constants``."""
    if isinstance(node, ast.Constant):
        return isinstance(node.value, (bool, int))
    if isinstance(node, ast.Name):
        return node.id in constants
    if isinstance(node, ast.UnaryOp):
        return _int_expression(node.operand, constants)
    if isinstance(node, ast.BinOp):
        return _int_expression(node.left, constants) and _int_expression(node.right, constants)
    return False


def _int_constants(tree, imported=()):
    """Names of the module-level int or bool constants (`K = 3`, `A = B + 16`, `X, Y = 0, 1`,
    `A, B = range(2)`; ``imported``: constant names imported from other modules): numba
    reads a global as a compile-time constant, a literal."""
    constants = set(imported)
    for node in tree.body:
        if not isinstance(node, ast.Assign) or len(node.targets) != 1:
            continue
        target, value = node.targets[0], node.value
        if isinstance(target, ast.Name) and _int_expression(value, constants):
            constants.add(target.id)
        elif isinstance(target, ast.Tuple):
            if isinstance(value, ast.Tuple):
                constants |= {t.id for t, v in zip(target.elts, value.elts)
                              if isinstance(t, ast.Name) and _int_expression(v, constants)}
            elif isinstance(value, ast.Call) and getattr(value.func, "id", "") == "range":
                constants |= {t.id for t in target.elts if isinstance(t, ast.Name)}
    return constants


def _literal(arg, constants):
    """True for an int or bool constant: 1, -1, True, or a module-level constant's name."""
    if isinstance(arg, ast.UnaryOp) and isinstance(arg.op, ast.USub):
        arg = arg.operand
    if isinstance(arg, ast.Constant):
        return isinstance(arg.value, (bool, int))
    return isinstance(arg, ast.Name) and arg.id in constants


def test_kernels_call_kernels_with_typed_arguments():
    modules = _kernels()
    found = []
    for path, (_, kernels, constants, imported) in modules.items():
        for caller in kernels.values():
            for node in ast.walk(caller):
                if not isinstance(node, ast.Call) or not isinstance(node.func, ast.Name):
                    continue
                callee = kernels.get(node.func.id)
                if callee is None and node.func.id in imported:
                    file, name = imported[node.func.id]
                    callee = modules.get(file, (None, {}))[1].get(name)
                if callee is None:
                    continue
                where = f"{path.relative_to(SRC)}:{node.lineno} {caller.name} -> {callee.name}"
                known = constants | {name for name, (file, there) in imported.items()
                                     if there in modules.get(file, (None, None, set()))[2]}
                for i, arg in enumerate(node.args):
                    if _literal(arg, known):
                        found.append(f"{where}: argument {i + 1} is the constant {ast.unparse(arg)}")
                n_params = len(callee.args.args)
                n_given = len(node.args) + len(node.keywords)
                if n_given < n_params and not any(isinstance(a, ast.Starred) for a in node.args):
                    found.append(f"{where}: {n_params - n_given} defaulted argument(s) left out")
    assert not found, "constant or omitted arguments (np.int64(...), np.bool_(...), or pass the default):\n" + \
        "\n".join(found)


def test_the_check_finds_a_constant_argument(tmp_path):
    """The check itself: a literal, a negative literal, a module constant and an omitted
    default are found; np.int64(1) and a variable are not."""
    source = ("import numpy as np\nfrom numba import njit\nK = 3\n"
              "@njit\ndef callee(x, order, tol=1e-9):\n    return x\n"
              "@njit\ndef caller(x, n):\n"
              "    return callee(x, 1, 0.1) + callee(x, -1, 0.1) + callee(x, K, 0.1) + callee(x, n)"
              " + callee(x, np.int64(1), 0.1) + callee(x, n, 0.1)\n")
    tree = ast.parse(source)
    kernels = {f.name: f for f in tree.body if isinstance(f, ast.FunctionDef)}
    calls = [c for c in ast.walk(kernels["caller"])
             if isinstance(c, ast.Call) and getattr(c.func, "id", "") == "callee"]
    flags = [(any(_literal(a, {"K"}) for a in c.args), len(c.args) < 3) for c in calls]
    assert sorted(flags) == sorted([(True, False), (True, False), (True, False), (False, True), (False, False),
                                    (False, False)])
