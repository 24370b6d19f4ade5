"""A policy built by the user's own Python code: `FILE.py:NAME`.

`NAME` is a function in `FILE.py` that takes no arguments and returns a torch `nn.Module`
(observation batch (B, *obs_shape) as float32 tensor -> outputs (B, k)) or any callable on
numpy batches. The outputs are scores of the scenario's discrete actions (the policy takes
the argmax) or the continuous action itself. **This runs the file's code, by design**: name
only files you would run yourself. SB3 zips are read without running anything; this is the
one door that runs code, and it is opened only by writing `FILE.py:NAME`.
"""

from __future__ import annotations

import hashlib
import importlib.util
import re
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from zodrive.errors import ZodriveError, cause

if TYPE_CHECKING:
    from zodrive.attacks.victim import Victim

PATTERN = re.compile(r"^(?P<file>.+\.py):(?P<name>[A-Za-z_]\w*)$")


def is_factory(model: str) -> bool:
    return bool(PATTERN.match(str(model)))


def split_factory(model: str) -> tuple[Path, str]:
    """(resolved file, function name) of `FILE.py:NAME`; the file must exist."""
    match = PATTERN.match(str(model))
    if match is None:
        raise ZodriveError(f"{model!r} is not FILE.py:NAME")
    file = Path(match["file"]).resolve()
    if not file.is_file():
        raise ZodriveError(f"policy file not found: {match['file']}")
    return file, match["name"]


def build(model: str) -> Any:
    """Import FILE.py (runs it) and call NAME(); one-line errors for what goes wrong."""
    file, name = split_factory(model)
    module_name = "zodrive_user_" + hashlib.sha256(str(file).encode()).hexdigest()[:12]
    spec = importlib.util.spec_from_file_location(module_name, file)
    if spec is None or spec.loader is None:
        raise ZodriveError(f"{file} cannot be imported as Python")
    module = importlib.util.module_from_spec(spec)
    sys.modules[module_name] = module  # dataclasses and pickling inside the user's file need it
    try:
        spec.loader.exec_module(module)
        factory = getattr(module, name, None)
        if not callable(factory):
            raise ZodriveError(f"{file} has no function {name!r}")
        return factory()
    except ZodriveError:
        raise
    except SystemExit as exc:  # sys.exit() in the user's file would end zodrive with its code and no word
        raise ZodriveError(f"{model}: the policy code called sys.exit({exc.code!r}) while being loaded") from None
    except Exception as exc:  # noqa: BLE001 - the user's code may raise anything
        raise ZodriveError(f"{model}: the policy code raised {cause(exc)}") from exc


def factory_victim(model: str, preset: dict[str, Any]) -> Victim:
    """The victim of `FILE.py:NAME` for a preset's scenario, its outputs checked on one batch."""
    from zodrive.policies.victims import object_victim

    return object_victim(build(model), preset, model)
