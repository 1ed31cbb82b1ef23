/* Not linked: compiled for the Cortex-M4F only so that make size-m4 reads
 * sizeof(bl_filter), sizeof(bl_sequencer) and sizeof(bl_localizer) from the
 * symbol sizes (nm -S) of these three objects. */
#include "beaconloc/localizer.h"

bl_filter size_probe_filter;
bl_sequencer size_probe_sequencer;
bl_localizer size_probe_localizer;
