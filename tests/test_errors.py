"""Every error class crackgen defines inherits CrackgenError, so one ``except`` catches them all.

The classes are found by walking the package, so a new module whose error forgets the base
fails here without anyone having to list it.
"""
import importlib
import inspect
import pkgutil

import pytest

import crackgen
from crackgen.errors import CrackgenError


def _crackgen_exception_classes() -> dict[str, type]:
    """Exception subclasses defined (not just imported) in any crackgen module, by qualified name.

    Warning subclasses are left out: they are emitted with ``warnings.warn``, never raised as a
    refusal, so a single ``except CrackgenError`` has no business catching them.
    """
    found = {}
    for info in pkgutil.walk_packages(crackgen.__path__, "crackgen."):
        module = importlib.import_module(info.name)
        for _, obj in inspect.getmembers(module, inspect.isclass):
            if obj.__module__ == module.__name__ and issubclass(obj, Exception) and not issubclass(obj, Warning):
                found[f"{obj.__module__}.{obj.__qualname__}"] = obj
    return found


CLASSES = _crackgen_exception_classes()


def test_walk_finds_the_known_error_classes():
    names = {name.rsplit(".", 1)[1] for name in CLASSES}
    assert {"RecipeError", "ShardError", "SensorError", "PipelineError", "RenderError"} <= names, sorted(names)


@pytest.mark.parametrize("name", sorted(CLASSES))
def test_error_class_inherits_crackgen_error(name):
    assert issubclass(CLASSES[name], CrackgenError), f"{name} must inherit crackgen.errors.CrackgenError"


def test_trainer_input_error_is_a_crackgen_error():
    from trainer.core.errors import TrainerInputError

    assert issubclass(TrainerInputError, CrackgenError) and issubclass(TrainerInputError, ValueError)
