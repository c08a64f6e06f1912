"""The product's measures of a motion: pose metrics, gait from a motion or from a sensor's own
signal, strides. The app reports them; the lab compares methods with them."""
