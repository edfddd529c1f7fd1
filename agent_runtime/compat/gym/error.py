"""gym's error base."""


class Error(Exception):
    pass
