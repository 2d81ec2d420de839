"""Every number of the synthetic-floor generator, in one typed, frozen configuration.

These numbers describe *how synthetic floors look* (sizes of rooms, walls, doors, furniture, the
simulated laser and SLAM noise), not the semantic model that is estimated from maps, so they live
here with their defaults in code (kiss-icp style) rather than in ``models/``. Lengths are metres,
probabilities are per item. ``docs/synthetic.md`` explains each group.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class SynthParams:
    """Configuration of :func:`semmap_pp.synth.generate_floor` (all lengths in metres)."""

    # --- units -------------------------------------------------------------------------------
    room_min: float = 2.5             # side length of an ordinary room
    room_max: float = 8.0
    room_depth_min: float = 3.0       # depth of a row of rooms off a corridor
    room_depth_max: float = 7.0
    room_depth_jitter: float = 1.0    # some rooms of a row are deeper or shallower than the row
    p_room_depth_jitter: float = 0.3
    corridor_width_min: float = 1.5
    corridor_width_max: float = 3.0
    hall_min: float = 8.0             # shorter side of a hall
    hall_max: float = 20.0
    block_depth_min: float = 7.0      # grid layout: distance between parallel corridors
    block_depth_max: float = 14.0
    room_width_mean_min: float = 3.6  # mean room width used to size a layout for a unit count
    room_width_mean_max: float = 5.2
    p_spine_hall: float = 0.35        # a spine ends in a hall
    p_spine_two_sided: float = 0.8    # small spines (<= 8 units) have rooms on both sides
    p_open_junction: float = 0.6      # a corridor opens into its hall without a wall
    p_l_shape: float = 0.35           # chance that a wide room slot becomes an L (two units)
    l_min_leftover: float = 2.0       # depth of the small unit left behind an L's short arm
    units_min_default: int = 6        # unit count drawn when the caller gives none
    units_max_default: int = 26
    # layout kinds and their weights: corridor spine, grid of corridors, hall with rooms around
    layout_weights: tuple[float, float, float] = (0.45, 0.3, 0.25)
    grid_min_units: int = 14          # below this a grid of corridors makes no sense

    # --- walls, doors, windows ---------------------------------------------------------------
    wall_inner_min: float = 0.10
    wall_inner_max: float = 0.20
    wall_outer_min: float = 0.20
    wall_outer_max: float = 0.30
    door_min: float = 0.7
    door_max: float = 1.5
    door_margin: float = 0.3          # free wall between a door and the end of its wall
    p_extra_door: float = 0.15        # additional door on a room–corridor/hall wall
    p_extra_room_door: float = 0.08   # additional door between two rooms
    p_door_closed: float = 0.12       # a room door is closed while mapping (room stays unknown)
    p_window: float = 0.35            # an exterior wall of a room/hall has windows
    window_min: float = 0.8
    window_max: float = 2.5
    window_spacing_min: float = 2.5   # one window per this much exterior wall
    window_spacing_max: float = 4.5
    p_glass_reflects: float = 0.9     # a laser ray is stopped by window glass
    p_exit: float = 0.25              # a corridor/hall end on the outline has an open exit door

    # --- furniture ---------------------------------------------------------------------------
    furniture_per_m2: float = 0.18    # blobs (desks, cabinets) per square metre of room
    legs_per_m2: float = 0.12         # tables/chairs seen only as legs
    clutter_per_m2: float = 0.30      # small things: bins, boxes, bags (0.1-0.3 m)
    p_pilasters: float = 0.35         # a unit's walls carry columns / radiators at intervals
    pilaster_spacing_min: float = 2.0
    pilaster_spacing_max: float = 4.5
    pillar_spacing_min: float = 4.0   # halls: pillars on a grid
    pillar_spacing_max: float = 7.0
    p_hall_pillars: float = 0.5
    p_corridor_object: float = 0.04   # objects per metre of corridor

    # --- robot, laser, SLAM noise ------------------------------------------------------------
    pose_spacing: float = 0.5         # distance between scans along the path
    hall_lane_min: float = 2.5        # distance between the robot's lanes through a hall
    hall_lane_max: float = 4.0
    p_enter_room: float = 0.65        # the robot drives into a reachable room (else glimpses it)
    laser_range_min: float = 8.0
    laser_range_max: float = 15.0
    laser_rays: int = 360             # rays per scan over 360 degrees
    range_sigma_min: float = 0.015    # range noise, drawn per floor (map quality varies)
    range_sigma_max: float = 0.035
    hit_depth_max: float = 0.1        # a reading also marks up to this far behind its end (drawn
                                      # per floor: thin map_saver walls to thick GMapping walls)
    pose_sigma_xy: float = 0.015      # registration error of a scan
    pose_sigma_deg: float = 0.15
    p_ray_dropout: float = 0.03       # no return for a ray
    outside_clutter: float = 0.012    # density of obstacles outside the building (cells)
    occupied_ratio: float = 0.15      # hits / (hits + passes) from which a cell is occupied
    free_ratio: float = 0.05          # ... up to which it is free (between: unknown, as map_server)
    p_speckle_occupied: float = 0.001 # free cell shown occupied
    p_speckle_unknown: float = 0.002  # free cell shown unknown
    p_wall_dropout: float = 0.04      # occupied cell lost (unknown)
    map_margin_min: float = 0.5       # grey border around the known part of the map
    map_margin_max: float = 2.0
    max_outside: float = 4.0          # rays beyond this distance from the building are cropped
    p_axis_aligned: float = 0.35      # rotation 0 when none is given
    p_right_angle: float = 0.15       # rotation 90 / 180 / 270 when none is given

    # --- wings (generate_floor(wings=K), K >= 2) ----------------------------------------------
    wing_angle_min: float = 15.0      # angle of a wing against the one before, when none is given
    wing_angle_max: float = 75.0
