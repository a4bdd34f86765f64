"""Stage reports: ``reports/<stage>/report.md`` (+ PNGs beside it) and ``metrics.json``."""

from pathlib import Path

from skt_lib.io import write_json_atomic, write_text_atomic


class Report:
    """Markdown assembled section by section; figures referenced by relative path."""

    def __init__(self, stage: str, directory: str | Path):
        self.stage = stage
        self.dir = Path(directory)
        self.dir.mkdir(parents=True, exist_ok=True)
        self._parts = [f"# Stage `{stage}`\n"]

    def text(self, markdown: str) -> None:
        self._parts.append(markdown.rstrip() + "\n")

    def heading(self, title: str) -> None:
        self._parts.append(f"## {title}\n")

    def table(self, header: list[str], rows: list[list[object]]) -> None:
        def cell(x):
            return f"{x:.4g}" if isinstance(x, float) else str(x)

        lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
        lines += ["| " + " | ".join(cell(x) for x in row) + " |" for row in rows]
        self._parts.append("\n".join(lines) + "\n")

    def figure(self, filename: str, caption: str) -> Path:
        """Reference ``filename`` (to be written into the report dir); returns its path."""
        self._parts.append(f"![{caption}]({filename})\n\n*{caption}*\n")
        return self.dir / filename

    def recording(self, timeline: str) -> None:
        """The section showing the stage's Rerun recording: ``rerun.png``, a screenshot of
        ``data/<stage>/<stage>.rrd`` in Rerun's web viewer, written by ``make review``."""
        self.heading("Rerun recording")
        self.text(f"`data/{self.stage}/{self.stage}.rrd` shows one item at a time: step the "
                  f"`{timeline}` timeline to go from item to item (`rerun data/{self.stage}/"
                  f"{self.stage}.rrd`). Below, the recording as Rerun's web viewer opens it "
                  f"(screenshot by `make review`, in headless Chromium).")
        self._parts.append(f"![{self.stage} in Rerun](rerun.png)\n")

    def write(self) -> Path:
        path = self.dir / "report.md"
        write_text_atomic(path, "\n".join(self._parts))
        return path


def write_run_log(directory: str | Path, stage: str, entry: dict) -> Path:
    """``<directory>/<stage>.json``: a run's wall-clock figures, kept out of what git and DVC
    track (they change on every run)."""
    path = Path(directory) / f"{stage}.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    write_json_atomic(path, entry)
    return path


def write_metrics(directory: str | Path, metrics: dict) -> Path:
    path = Path(directory) / "metrics.json"
    write_json_atomic(path, metrics)
    return path
