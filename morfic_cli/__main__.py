"""``python -m morfic_cli``: the same entry point as the ``morfic`` console script."""

from morfic_cli.cli import main

if __name__ == "__main__":
    main()
