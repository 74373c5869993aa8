"""The studio's workspaces beyond strokes and bark, one module each: request bodies, the jobs
they queue (checked before queueing, each returning a :data:`~phloem.studio.jobs.Work`) and their
endpoints, mounted by :func:`phloem.studio.create_app`."""
