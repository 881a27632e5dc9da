"""Post-render image stages on the RGB views only (labels, depth and sensors untouched):
camera effects ([camera_effects]), then appearance adaptation toward a user's unlabeled photos ([adapt])."""
