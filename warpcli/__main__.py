"""``python -m warpcli``: the ``warp`` command."""

if __name__ == "__main__":
    from warpcli._entry import run

    run()
