"""Physics as small objects that take numbers and carry everything about themselves.

Nothing here knows about meshes, time steps, scenes or files: a material maps a
strain to a stress (:mod:`.kelvin_voigt`), a contact law maps the displacement on
the contact side to a traction and knows its slope and which components it acts
on (:mod:`.contact`, the laws in :mod:`.laws`), the bonding law maps the state to
a debonding rate and knows its time updates (:mod:`.bonding`), a relaxation kernel
knows its memory term (:mod:`.memory`), the compliant layer of Model B knows its
nodal law (:mod:`.unilateral`). :mod:`workbench.input.models` builds them from a scene.
"""
