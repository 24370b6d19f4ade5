"""The attack registry: one name per attack, used by code, configs and the CLI."""

from __future__ import annotations

from typing import Any

from zodrive.attacks.base import Attack
from zodrive.attacks.boundary import HopSkipJump
from zodrive.attacks.coordinate import CoordinateFD
from zodrive.attacks.hold import VertexCheck, VertexHold
from zodrive.attacks.learned import LearnedAdversary
from zodrive.attacks.nes import NES
from zodrive.attacks.noise import UniformNoise
from zodrive.attacks.pgd import FGSM, PGD
from zodrive.attacks.random_search import RandomSearch
from zodrive.attacks.spsa import SPSA
from zodrive.attacks.threat import ThreatModel
from zodrive.attacks.transfer import Transfer
from zodrive.attacks.zo_sgd import ZOSGD
from zodrive.attacks.zo_signsgd import ZOSignSGD
from zodrive.errors import ZodriveError

ATTACKS: dict[str, type[Attack]] = {
    cls.name: cls
    for cls in (ZOSignSGD, ZOSGD, NES, SPSA, RandomSearch, CoordinateFD, UniformNoise, FGSM, PGD, VertexHold,
                VertexCheck, HopSkipJump)
}

FOLDER_ONLY: dict[str, type[Attack]] = {LearnedAdversary.name: LearnedAdversary, Transfer.name: Transfer}
"""The attacks that run only from a trained folder (`NAME:DIR`), outside the registry of attacks that run from
nothing but their options."""

PICKER_ATTACKS = tuple(name for name, cls in ATTACKS.items() if cls.trained == "picker")  # NAME:DIR: a picker
KNOWN = (*(name for name in ATTACKS if name != VertexCheck.name), "learned:DIR",
         *(f"{name}:DIR" for name in PICKER_ATTACKS), "transfer:DIR")
"""Every attack name: the attacks above (ten searches, one of them decision-based (hsja), and vertex
hold; vertex check runs only with a picker), the learned adversary (`learned`, read from a folder
`zodrive attack-train` wrote; `zodrive.attacks.learned`), which has no place in the registry of
attacks that run from nothing but their options, and vertex hold and vertex check with a picker
(`vertex-hold:DIR`, `vertex-check:DIR`, fitted by `zodrive picker-train`; `zodrive.attacks.picker`), and transfer
from a surrogate (`transfer:DIR`, fitted by `zodrive surrogate-train`; `zodrive.attacks.transfer`)."""


def attack_class(name: str) -> type[Attack]:
    """The class of attack `name`: the registry's, or the learned adversary's or transfer's (read from a
    trained folder); its traits (`Attack.trained`, `goal`, `black_box`, ...) say what it needs and does."""
    found = FOLDER_ONLY.get(name) or ATTACKS.get(name)
    if found is None:
        raise ZodriveError(f"unknown attack {name!r} (known: {', '.join(KNOWN)})")
    return found


def make_attack(name: str, threat: ThreatModel, **hyper: Any) -> Attack:
    """Build an attack by name with validated hyperparameters (`learned` needs `adversary`)."""
    cls = attack_class(name)
    if name != "vertex-check" and hyper.pop("check_below", None) is not None:
        raise ZodriveError(f"check_below (a picker's rating) applies to vertex-check:DIR, not {name}")
    if cls is not LearnedAdversary:
        hyper.pop("load_network", None)  # only a learned adversary reads a network from a folder
    if not cls.trained and hyper.pop("adversary", None) is not None:  # NAME:DIR reads a trained folder
        raise ZodriveError(f"adversary (a trained folder) applies to learned:DIR, vertex-hold:DIR, "
                           f"vertex-check:DIR and transfer:DIR, not {name}")
    return cls(threat, **hyper)
