"""The ``skt`` console script: predict on a user's cloud, import a user's hook or object,
hang an object and record the rollout. A thin layer like ``stages/``: parse, call
``skt_lib``, print. Expected errors are one ``ERROR:`` line and exit code 2."""
