"""The contact laws of Model A, one file each; every :class:`~workbench.physics.contact.ContactTerm` subclass
defined in a module of this package is found here (a new law is one new file: its class, its parameters and how
a scene declares it; nothing else changes).

Built in: :class:`NormalCompliance` (the foundation's push), :class:`AdhesivePull` (the glue's normal pull, with
the bonding law), :class:`TangentialGlue` (the glue's tangential stiffness) and :class:`PowerLawPull` (an adhesive
pull with an exponent: the example of a law added in its own file).

Examples
--------
>>> [law.name for law in LAWS]
['compliance', 'adhesion', 'power_pull', 'glue']
"""
from __future__ import annotations

import importlib
import pkgutil

from ..contact import ContactTerm
from .adhesion import AdhesivePull
from .compliance import NormalCompliance
from .glue import TangentialGlue


def _discover() -> list:
    found = []
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda i: i.name):
        module = importlib.import_module(f"{__name__}.{info.name}")
        for obj in vars(module).values():
            if isinstance(obj, type) and issubclass(obj, ContactTerm) and obj.__module__ == module.__name__:
                found.append(obj)
    return sorted(found, key=lambda law: (law.rank, law.name))


#: Every contact law, in summation order.
LAWS = _discover()

__all__ = ["LAWS", "NormalCompliance", "AdhesivePull", "TangentialGlue"]
