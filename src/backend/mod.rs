//! The trainable grey-box network (the only module that names `dfdx`).
