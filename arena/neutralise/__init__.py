"""Team text made harmless for each place it is shown: one module per kind of sink.

- :mod:`~arena.neutralise.names`: names (team, method) refuse what makes one text look like
  another (bidirectional controls, zero-width and other invisible characters) at intake.
- :mod:`~arena.neutralise.spreadsheet`: CSV cells never start a formula.
- :mod:`~arena.neutralise.console`: Rich markup escaped and control characters stripped before
  the terminal sees them.
- :mod:`~arena.neutralise.storable`: NULs and lone surrogates replaced, so that any agent text
  can be stored (every database, every file written as UTF-8) and printed.
- :mod:`~arena.neutralise.log_view`: escape sequences and control characters of an agent's log
  made visible, not interpreted, in organisers' log views.

Web pages need no module here: Jinja2 escapes every value (autoescape) and the CSP forbids
inline script.
"""
