"""What the tests of tools/scripts/ share: a script loaded as a module by its path, checks that
record their failures and go on, and the exit status that reports them. Module state, for one
test process at a time.
"""
import importlib.util
import os

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "..")
failures = []


def script_path(name):
    """tools/scripts/NAME.py."""
    return os.path.join(ROOT, "tools", "scripts", name + ".py")


def load(name):
    """tools/scripts/NAME.py as a module."""
    spec = importlib.util.spec_from_file_location(name, script_path(name))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def check(condition, message):
    if not condition:
        failures.append(message)
        print("FAIL:", message)


def finish():
    """The exit status: 1 after any failed check, else 0; says which."""
    if failures:
        print("{} failure(s)".format(len(failures)))
        return 1
    print("all passed")
    return 0
