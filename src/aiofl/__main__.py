"""``python -m aiofl``: the same command line as the ``aiofl`` script."""

from aiofl.cli import main

if __name__ == "__main__":
    main()
