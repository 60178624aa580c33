"""Run the jobs of ``morfic reproduce`` on a Ray cluster (``--executor ray``); docs/cluster.md.

* :mod:`~morfic_cli.cluster.jobs`: the job graph of a pipeline (pure; no Ray) and what the store already holds.
* :mod:`~morfic_cli.cluster.worker`: the body of one job on a worker: its own store, input bundles in, the job's
  refs out as one export bundle.
* :mod:`~morfic_cli.cluster.ray_executor`: the driver: submits the jobs as Ray tasks in dependency order, imports
  each bundle into the user's store as it arrives, draws the progress view, cancels on Ctrl-C.

Ray is optional (``pip install 'morfic[cluster]'``); nothing here imports it at module level.
"""
