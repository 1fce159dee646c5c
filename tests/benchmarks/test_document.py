"""docs/BENCHMARKS.md blocks: a partial run replaces its sections and keeps the others."""

from benchmarks.document import body, compose, read_blocks

ORDER = ("step", "live", "paper")


def test_blocks_round_trip_and_a_partial_update_keeps_the_rest():
    blocks = {
        ("summary", "step"): body(["- Speed: 25x."]),
        ("bench", "step"): body(["## Tracker step", "", "| a | b |"]),
        ("summary", "live"): body([]),
        ("bench", "live"): body(["## Live", "p95 18 ms"]),
    }
    text = compose(["# Benchmarks", "intro"], ORDER, blocks)
    assert read_blocks(text) == blocks
    assert text.index("- Speed: 25x.") < text.index("## Tracker step") < text.index("## Live")
    # measure live again: step stays word for word, live is replaced, paper still absent
    again = read_blocks(text)
    again["bench", "live"] = body(["## Live", "p95 21 ms"])
    text2 = compose(["# Benchmarks", "intro"], ORDER, again)
    assert "p95 21 ms" in text2 and "p95 18 ms" not in text2
    assert read_blocks(text2)["bench", "step"] == blocks["bench", "step"]
    assert "paper" not in text2


def test_sections_print_in_the_given_order_whatever_order_they_were_measured_in():
    blocks = {("bench", "paper"): body(["P"]), ("bench", "step"): body(["S"])}
    text = compose(["# B"], ORDER, blocks)
    assert text.index("S\n") < text.index("P\n")
