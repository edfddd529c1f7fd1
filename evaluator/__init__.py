"""Evaluation: sandboxes, the runner that plays a submission through a suite, scoring, ranking
and the Celery tasks of the service."""
