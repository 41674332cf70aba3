"""The type stubs (bindings/python/fastslam/_fastslam.pyi) name what the module has: every
public name and method of the extension is in the stubs, and every stubbed one exists."""

from __future__ import annotations

import ast
import pathlib

import fastslam
from fastslam import _fastslam


def stubbed():
    path = pathlib.Path(fastslam.__file__).with_name("_fastslam.pyi")
    tree = ast.parse(path.read_text())
    names, members = set(), {}
    for node in tree.body:
        if isinstance(node, ast.ClassDef):
            names.add(node.name)
            members[node.name] = {n.name for n in node.body if isinstance(n, ast.FunctionDef)}
        elif isinstance(node, ast.FunctionDef):
            names.add(node.name)
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.add(node.target.id)
    return names, members


def public(obj):
    return {n for n in dir(obj) if not n.startswith("_")}


def test_stubs_match_module():
    names, members = stubbed()
    assert public(_fastslam) | {"__version__"} == names
    for cls, methods in members.items():
        assert public(getattr(_fastslam, cls)) == methods - {"__init__", "__len__"}, cls


def test_package_exports():
    assert set(fastslam.__all__) <= set(dir(fastslam))
    assert fastslam.__version__
