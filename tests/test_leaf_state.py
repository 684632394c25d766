"""The gate of "state declared in constructors, no Python objects changed inside updates"
(issue 32; docs/ARCHITECTURE.md, "Conventions").

Every module of ``handle_drake`` is parsed (not imported). In each class that derives from
``LeafSystem`` (directly, or through another class of the package that does, or mixes into
one), the callbacks are the methods and lambdas handed to a ``self.Declare...`` call (events,
output ports) and every method they call through ``self.``. A callback may read ``self``'s
attributes but not change them: no ``self.x = ...`` / ``self.x += ...`` /
``self.x[i] = ...``, no mutating method call (``append``, ``update``, ``clear``, ...) on
``self.x`` or on a local name bound to ``self.x`` (``d = self._decoder; d.count = 0``), no
``setattr(self, ...)``. What a trial changes lives in the context (discrete or abstract
state), so a fresh context is a fresh run and a diagram can be simulated twice.

``ALLOWED`` lists the justified exceptions, each with its reason.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "handle_drake"

# Methods that change the object they are called on (list, dict, set, deque, array).
MUTATORS = frozenset({
    "append", "extend", "insert", "pop", "popleft", "appendleft", "remove", "clear",
    "update", "setdefault", "add", "discard", "sort", "reverse", "fill", "resize",
    "__setitem__", "__delitem__",
})

# (module relative to handle_drake/, class, method) -> why the change is justified.
ALLOWED: dict[tuple[str, str, str], str] = {
    ("apps/inhand/gist.py", "GistMotionSource", "_frames"):
        "a cache of the pure function frames(gist, c, q0, N, ratio), keyed by the bytes of "
        "the parameter vector c read from the context: any context gets the frames of its "
        "own parameters, so no trial's result depends on it (Algorithm 1's N frames are "
        "computed once per trial, not once per output evaluation)",
}


def _self_attr(node) -> str | None:
    """``x`` of ``self.x``, ``self.x[...]``, ``self.x.y`` (the attribute of self reached)."""
    while isinstance(node, ast.Subscript | ast.Attribute):
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) \
                and node.value.id == "self":
            return node.attr
        node = node.value
    return None


def _root_name(node) -> str | None:
    while isinstance(node, ast.Subscript | ast.Attribute):
        node = node.value
    return node.id if isinstance(node, ast.Name) else None


def _mutations(func) -> list[tuple[int, str]]:
    """``(line, what)`` of each change to ``self``'s attributes inside ``func``."""
    aliases: dict[str, str] = {}  # local name -> self attribute it was bound to
    for node in ast.walk(func):
        if isinstance(node, ast.Assign) and len(node.targets) == 1 \
                and isinstance(node.targets[0], ast.Name) \
                and isinstance(node.value, ast.Attribute) \
                and isinstance(node.value.value, ast.Name) and node.value.value.id == "self":
            aliases[node.targets[0].id] = node.value.attr

    def owner(target) -> str | None:
        attr = _self_attr(target)
        if attr is not None:
            return f"self.{attr}"
        if isinstance(target, ast.Subscript | ast.Attribute):
            root = _root_name(target)
            if root in aliases:
                return f"self.{aliases[root]} (as {root})"
        return None

    out = []
    for node in ast.walk(func):
        targets = []
        if isinstance(node, ast.Assign):
            targets = node.targets
        elif isinstance(node, ast.AugAssign | ast.AnnAssign):
            targets = [node.target]
        elif isinstance(node, ast.Delete):
            targets = node.targets
        for target in targets:
            for t in (target.elts if isinstance(target, ast.Tuple | ast.List) else [target]):
                who = owner(t)
                if who is not None:
                    out.append((node.lineno, f"assigns {who}"))
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute):
            if node.func.attr in MUTATORS:
                who = owner(node.func.value) if isinstance(
                    node.func.value, ast.Attribute | ast.Subscript) else None
                if who is None and isinstance(node.func.value, ast.Name) \
                        and node.func.value.id in aliases:
                    who = f"self.{aliases[node.func.value.id]} (as {node.func.value.id})"
                if who is not None:
                    out.append((node.lineno, f"calls {who}.{node.func.attr}()"))
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) \
                and node.func.id == "setattr" and node.args \
                and isinstance(node.args[0], ast.Name) and node.args[0].id == "self":
            out.append((node.lineno, "setattr(self, ...)"))
    return out


def _base_names(cls: ast.ClassDef) -> list[str]:
    return [b.id if isinstance(b, ast.Name) else b.attr for b in cls.bases
            if isinstance(b, ast.Name | ast.Attribute)]


def _classes() -> dict[str, tuple[str, ast.ClassDef]]:
    """``"module:Class"`` -> (module, class definition), modules relative to handle_drake/."""
    out = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        module = str(path.relative_to(PACKAGE))
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if isinstance(node, ast.ClassDef):
                out[f"{module}:{node.name}"] = (module, node)
    return out


def _bases(key, classes) -> list[str]:
    """Keys of ``key``'s bases defined in the package (the same module's first)."""
    module, cls = classes[key]
    out = []
    for name in _base_names(cls):
        same = f"{module}:{name}"
        if same in classes:
            out.append(same)
        else:
            out += [k for k in classes if k.endswith(f":{name}")][:1]
    return out


def _leaf_systems(classes) -> list[str]:
    """Keys of the classes deriving from LeafSystem (transitively through the package's)."""
    leaf = set()
    changed = True
    while changed:
        changed = False
        for key, (_, cls) in classes.items():
            if key not in leaf and ("LeafSystem" in _base_names(cls)
                                    or any(b in leaf for b in _bases(key, classes))):
                leaf.add(key)
                changed = True
    return sorted(leaf)


def _methods(key, classes, seen=None) -> dict[str, tuple[str, str, ast.FunctionDef]]:
    """method name -> (module, class, def), the class's own first, then its bases'."""
    seen = set() if seen is None else seen
    if key not in classes or key in seen:
        return {}
    seen.add(key)
    module, cls = classes[key]
    out = {}
    for base in reversed(_bases(key, classes)):
        out.update(_methods(base, classes, seen))
    for node in cls.body:
        if isinstance(node, ast.FunctionDef):
            out[node.name] = (module, cls.name, node)
    return out


def _self_calls(node) -> set[str]:
    """Names ``m`` of ``self.m`` read anywhere in ``node`` (calls and references)."""
    return {n.attr for n in ast.walk(node) if isinstance(n, ast.Attribute)
            and isinstance(n.value, ast.Name) and n.value.id == "self"}


def callback_mutations() -> list[tuple[str, str, str, int, str]]:
    """``(module, class, callback, line, what)`` of every change to ``self`` in a callback."""
    classes = _classes()
    found = set()
    for name in _leaf_systems(classes):
        methods = _methods(name, classes)
        roots, lambdas = set(), []
        for _, _, method in methods.values():
            for call in ast.walk(method):
                if isinstance(call, ast.Call) and isinstance(call.func, ast.Attribute) \
                        and call.func.attr.startswith("Declare") \
                        and isinstance(call.func.value, ast.Name) and call.func.value.id == "self":
                    for arg in [*call.args, *(k.value for k in call.keywords)]:
                        if isinstance(arg, ast.Lambda):
                            lambdas.append((method, arg))
                            roots |= _self_calls(arg) & set(methods)
                        elif isinstance(arg, ast.Attribute) and isinstance(arg.value, ast.Name) \
                                and arg.value.id == "self" and arg.attr in methods:
                            roots.add(arg.attr)
        reached, todo = set(), list(roots)
        while todo:
            m = todo.pop()
            if m in reached or m == "__init__":
                continue
            reached.add(m)
            todo.extend(_self_calls(methods[m][2]) & set(methods))
        for m in reached:
            module, owner_cls, node = methods[m]
            for line, what in _mutations(node):
                found.add((module, owner_cls, m, line, what))
        for method, lam in lambdas:
            module, owner_cls, _ = methods[method.name]
            for line, what in _mutations(lam):
                found.add((module, owner_cls, "<lambda>", line, what))
    return sorted(found)


def test_the_scan_finds_leaf_systems_and_their_callbacks():
    classes = _classes()
    leaves = {key.split(":")[1] for key in _leaf_systems(classes)}
    # known systems of each area are seen (the scan cannot pass by finding nothing)
    for name in ("MidiControllerEncoder", "MidiReceiver", "MidiHandControl", "MidiPortWriter",
                 "ReactiveGrasp", "GuardedGrasp"):
        assert name in leaves, name


def test_the_scan_catches_each_kind_of_change(monkeypatch):
    src = (
        "class S(LeafSystem):\n"
        "    def __init__(self):\n"
        "        self._n = 0\n"
        "        self.DeclarePeriodicPublishEvent(0.1, 0.0, self._publish)\n"
        "        self.DeclareVectorOutputPort('y', 1, lambda c, o: self._log.append(c))\n"
        "    def _publish(self, context):\n"
        "        self._n = 1\n"
        "        self._helper()\n"
        "    def _helper(self):\n"
        "        self._count += 1\n"
        "        self._table['a'] = 2\n"
        "        self._seen.add(3)\n"
        "        d = self._decoder\n"
        "        d.accepted = 0\n"
        "        d.rejected.clear()\n"
    )
    classes = {"probe.py:S": ("probe.py", ast.parse(src).body[0])}
    monkeypatch.setitem(globals(), "_classes", lambda: classes)
    found = {(m, what) for _, _, m, _, what in callback_mutations()}
    assert found == {
        ("_publish", "assigns self._n"),
        ("_helper", "assigns self._count"),
        ("_helper", "assigns self._table"),
        ("_helper", "calls self._seen.add()"),
        ("_helper", "assigns self._decoder (as d)"),
        ("_helper", "calls self._decoder (as d).clear()"),
        ("<lambda>", "calls self._log.append()"),
    }


def test_no_leaf_system_callback_changes_python_attributes():
    bad = [f"{module}:{line} {cls}.{method} {what}"
           for module, cls, method, line, what in callback_mutations()
           if (module, cls, method) not in ALLOWED]
    assert not bad, ("LeafSystem callbacks change Python attributes (declare state instead, "
                     "or add a justified entry to ALLOWED):\n" + "\n".join(bad))


@pytest.mark.parametrize("key", sorted(ALLOWED))
def test_every_allowed_entry_is_still_needed(key):
    assert any(f[:3] == key for f in callback_mutations()), f"{key} no longer changes self"
