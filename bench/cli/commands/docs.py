"""``hilbench docs [TOPIC]``: list the documentation that ships with hilbench, or print one topic (docs/TOPIC.md)."""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("docs", help="list the shipped documentation, or print one topic",
                       description="The documentation (docs/*.md in the repository) ships with the package: "
                                   "'hilbench docs' lists its topics with their first line, 'hilbench docs TOPIC' "
                                   "prints one (e.g. 'hilbench docs metrics' for docs/metrics.md); '--path' "
                                   "prints where the installed files are.")
    p.add_argument("topic", nargs="?", default=None, help="a topic (file name without .md, e.g. metrics, cli)")
    p.add_argument("--path", action="store_true", help="print the folder of the installed docs")
    p.set_defaults(func=run)


def shipped() -> dict:
    """Topic -> the installed Markdown file (an importlib.resources traversable), by name."""
    from importlib.resources import files

    return {f.name[:-3]: f for f in sorted(files("hilbench.docs").iterdir(), key=lambda f: f.name)
            if f.is_file() and f.name.endswith(".md")}


def title(text: str) -> str:
    """The first heading (or line) of a Markdown text, without its #."""
    for line in text.splitlines():
        if line.strip():
            return line.lstrip("#").strip()
    return ""


def run(args: argparse.Namespace) -> int:
    from importlib.resources import files

    from hilbench.bench.errors import BenchError

    topics = shipped()
    if args.path:
        print(files("hilbench.docs"))
        return 0
    if args.topic is None:
        width = max(map(len, topics), default=0)
        for name, f in topics.items():
            print(f"{name:<{width}}  {title(f.read_text(encoding='utf-8'))}")
        return 0
    topic = args.topic.removeprefix("docs/").removesuffix(".md")
    if topic not in topics:
        raise BenchError(f"no documentation topic {args.topic!r}; the topics are {', '.join(topics)}")
    text = topics[topic].read_text(encoding="utf-8")
    print(text, end="" if text.endswith("\n") else "\n")
    return 0
