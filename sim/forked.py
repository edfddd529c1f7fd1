"""Imported last by the episodes' fork server (:func:`sim.isolation.preload_modules`), once the
preloaded modules are in: it moves every object they made out of the garbage collector's reach.

Each episode's process is forked from that server and shares its memory until it writes to it. A
collection in the child visits, and so writes to, every object it tracks: it would copy, page by
page, the server's whole heap into each episode (a few milliseconds of every start). Frozen
objects are never collected, which costs nothing for modules that live as long as the process.
"""

import gc

gc.freeze()
