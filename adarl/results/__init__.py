"""Reading finished run folders for everything after training (evaluation, report, summary):
`runs` finds run folders and labels them, `collect` reads their logs into tables. Writing a run
folder, and its format, is `adarl.runs` (docs/run-format.md)."""
