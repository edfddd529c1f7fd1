"""The job engine: every kind of sandboxed work a worker does (an upload's validation, an
episode, a training) claimed, leased, fenced, finished and reaped one way (:mod:`.engine`)."""
