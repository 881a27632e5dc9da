"""Image fusion of exposure and focus stacks (guided filter) and its no-reference quality scores."""
