"""How the engine's kernels are compiled: the numba options they share, in one place.

numba counts references to every array it hands around in compiled code: each time a
function receives a record (a named tuple of arrays) or copies it into an inlined callee,
every array in it is counted up and down again, with atomic instructions. The game's records
hold dozens of arrays, so in the engine's loop those counts cost more than the arithmetic
(on a six-generator feeder about two thirds of an evaluation). The loop allocates nothing and
returns no array: every array it touches is owned by the caller for the whole call. So the
loop is compiled without reference counting (:data:`BORROWING`), and the few functions it
calls that allocate say so (:data:`ALLOCATING`) and are compiled with it.

Safe by construction: numba refuses to compile an allocation in a function compiled
without reference counting, so a kernel that starts allocating fails to compile instead of
leaking or freeing early. Such a kernel takes the allocating part into a function of its
own marked :data:`ALLOCATING`, or is given the array by its caller.
"""

from __future__ import annotations

#: numba options of a kernel that only borrows arrays: it allocates nothing, keeps no array
#: beyond the call and returns none, so it is compiled without reference counting, and so are
#: the functions it calls unless they say otherwise.
BORROWING = {"_nrt": False}
#: numba options of a function that allocates (its scratch) and is called from a
#: :data:`BORROWING` kernel: compiled with reference counting, whatever its caller's.
ALLOCATING = {"_nrt": True}
