"""The evaluation worker: Celery tasks that drive :mod:`evaluator`'s core for the service."""
