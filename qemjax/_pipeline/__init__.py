"""One simplification run: settings, the stages of a run, the re-fit and split post-passes, the API."""
