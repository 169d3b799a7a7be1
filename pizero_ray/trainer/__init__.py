"""The Ray trainer: the driver, the elastic worker pool, worker actors and their local devices."""
