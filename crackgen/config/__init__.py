"""Recipe -> SampleSpec: validated recipes and every random draw of a sample."""
