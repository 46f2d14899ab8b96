"""``python -m viscx``: the same as the ``viscx`` console script."""

from viscx.cli import main

if __name__ == "__main__":
    main()
