"""The semantic map of a world: units in the image frame and in metres, their ids, rooms and regions, and the world.json document."""
