"""Post-render image stages on the RGB views only (labels, depth and sensors untouched):
appearance adaptation toward a user's unlabeled photos ([adapt])."""
