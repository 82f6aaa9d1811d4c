/* The hexapod plant's contact codes and how one contact is summed: the one definition every engine's C loop
   includes, and the one cpgsim.robots.description reads its CONTACT_* constants from (so Python and C cannot
   disagree). HexapodPlant.read_contacts (robots/plant_base.py) is the same rule in Python.

   Codes of the robot's shapes: a leg index 0-5 for a sensed toe (the foot sphere, and the tibia box with
   sense_shank), CPGSIM_CONTACT_LINK + leg for the leg's other links, CPGSIM_CONTACT_BODY for the body box,
   CPGSIM_CONTACT_OTHER for anything that is not the robot. */
#ifndef CPGSIM_PLANT_CONTACTS_H
#define CPGSIM_PLANT_CONTACTS_H

enum { CPGSIM_CONTACT_LINK = 10, CPGSIM_CONTACT_BODY = 100, CPGSIM_CONTACT_OTHER = 1000 };

/* One contact of the robot's shape with code `code`: a sensed toe's force (`sign` times the engine's contact
   force `f`, world frame, so that it is the force on the robot) is added to its leg's three sums in
   `force18`; returns 0 then. Otherwise returns 1 + the index of the flag the contact sets in a 7-flag array
   (0: the body touched something, 1 + leg: that leg's coxa or femur, or unsensed tibia, did). */
static inline int cpgsim_add_contact(int code, double sign, const double f[3], double force18[18]) {
  if (code < CPGSIM_CONTACT_LINK) {
    force18[3 * code] += sign * f[0];
    force18[3 * code + 1] += sign * f[1];
    force18[3 * code + 2] += sign * f[2];
    return 0;
  }
  if (code == CPGSIM_CONTACT_BODY) return 1;
  return 2 + code - CPGSIM_CONTACT_LINK;
}

#endif
