"""Neural and grey-box models of EAP actuators, datasets, training and the ``eap`` command line."""
