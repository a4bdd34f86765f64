"""The ``skt`` console script: predict on a user's cloud, import a user's hook or object,
hang an object and record the rollout. A thin layer like ``stages/``: parse, call
``skt_lib``, print. Expected errors are one ``ERROR:`` line and exit code 2. Beside the
commands: meshes like those users bring to them (``mesh_zoo``, ``example_hooks``), for the
tests, ``make bench`` and the README's walk-through."""
