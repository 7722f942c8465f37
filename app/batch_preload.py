"""What the local cluster's fork server imports for a batch's previews, besides the solve's modules
(``model.fork_server.WORKER_MODULES``): ``app.batch_worker`` (the compiled kernel that draws them, Pillow's PNG
writer) and ``app.cli_batch``, which the job's preview names. A module of its own, importing nothing, so that
``app.launch`` can start the fork server before anything else is imported."""
BATCH_PRELOAD = ("app.batch_worker", "app.cli_batch")
