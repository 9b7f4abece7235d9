"""`python -m gcdt` is the `gcdt` command."""

from gcdt.cli import main

# The guard matters: env worker processes are spawned, and spawn re-imports __main__.
if __name__ == "__main__":
    raise SystemExit(main())
