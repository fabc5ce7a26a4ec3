"""What a run leaves: sample files, the posterior file, comparisons with a true scene, reports."""
