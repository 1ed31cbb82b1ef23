# make install — the daemon, its systemd unit, its manual and example site files.
#   make install [PREFIX=/usr/local] [DESTDIR=] [SYSCONFDIR=/etc]
#     $(PREFIX)/bin/beaconloc-bridge                         the daemon (0755)
#     $(PREFIX)/lib/systemd/system/beaconloc-bridge.service  the unit, ExecStart and the
#                                                            site path set to this install
#     $(PREFIX)/share/man/man8/beaconloc-bridge.8            docs/bridge.md by pandoc
#     $(PREFIX)/share/beaconloc/sites/*.ini                  the example site files
#     $(PREFIX)/share/beaconloc/beaconloc.dbc                the CAN protocol (cantools, candump)
#     $(SYSCONFDIR)/beaconloc/site.ini                       kleeman-lab.ini, only where no
#                                                            site.ini is: an operator's is kept
#   make man       build/man/beaconloc-bridge.8 only
# DESTDIR is prepended to every path (staged installs, packaging); nothing is
# written outside it. systemd looks in /usr/local/lib/systemd/system and
# /usr/lib/systemd/system (PREFIX /usr/local or /usr). Tested by
# tests/bridge/test_install.py (make install into a DESTDIR, systemd-analyze
# verify and security, the man page through groff, the unit's system-call
# filter against every system call the daemon makes).

PREFIX          ?= /usr/local
SYSCONFDIR      ?= /etc
BINDIR          := $(PREFIX)/bin
UNITDIR         := $(PREFIX)/lib/systemd/system
MANDIR          := $(PREFIX)/share/man
SHAREDIR        := $(PREFIX)/share/beaconloc
INSTALL         ?= install
BRIDGE_MAN      := $(BUILD)/man/beaconloc-bridge.8
BRIDGE_UNIT     := bridge/beaconloc-bridge.service
# The example sites: one per kind of beacon system (ultrasonic TDOA, bearings,
# fixed range beacons, a team without fixed beacons).
INSTALL_SITES   := $(addprefix hw_sim/beaconloc_sim/data/scenarios/, \
                     kleeman-lab.ini eurobot.ini marvelmind.ini millibots-room.ini)
BRIDGE_VERSION_STR = $(shell sed -n 's/^#define BRIDGE_VERSION "\(.*\)"/\1/p' bridge/options.h)

.PHONY: install man
man: $(BRIDGE_MAN)

# docs/bridge.md is written as a manual page (NAME, SYNOPSIS, ... sections):
# its first line, the page's title, becomes pandoc's title metadata and its
# "##" sections the page's .SH sections.
$(BRIDGE_MAN): docs/bridge.md bridge/install.mk
	@mkdir -p $(@D)
	@command -v pandoc > /dev/null || { echo "make man: pandoc is missing (make setup installs it)"; exit 1; }
	sed 1d $< | pandoc --from gfm --to man --standalone --shift-heading-level-by=-1 \
	    --metadata title=BEACONLOC-BRIDGE --metadata section=8 \
	    --metadata header="beaconloc" --metadata footer="beaconloc-bridge $(BRIDGE_VERSION_STR)" \
	    --output $@

install: $(BRIDGE_BIN) $(BRIDGE_MAN)
	$(INSTALL) -d $(DESTDIR)$(BINDIR) $(DESTDIR)$(UNITDIR) $(DESTDIR)$(MANDIR)/man8 \
	    $(DESTDIR)$(SHAREDIR)/sites $(DESTDIR)$(SYSCONFDIR)/beaconloc
	$(INSTALL) -m 0755 $(BRIDGE_BIN) $(DESTDIR)$(BINDIR)/beaconloc-bridge
	sed -e 's|/usr/local/bin/beaconloc-bridge|$(BINDIR)/beaconloc-bridge|' \
	    -e 's|/etc/beaconloc/site.ini|$(SYSCONFDIR)/beaconloc/site.ini|' \
	    $(BRIDGE_UNIT) > $(DESTDIR)$(UNITDIR)/beaconloc-bridge.service.tmp
	chmod 0644 $(DESTDIR)$(UNITDIR)/beaconloc-bridge.service.tmp
	mv $(DESTDIR)$(UNITDIR)/beaconloc-bridge.service.tmp $(DESTDIR)$(UNITDIR)/beaconloc-bridge.service
	$(INSTALL) -m 0644 $(BRIDGE_MAN) $(DESTDIR)$(MANDIR)/man8/beaconloc-bridge.8
	$(INSTALL) -m 0644 $(INSTALL_SITES) $(DESTDIR)$(SHAREDIR)/sites/
	$(INSTALL) -m 0644 $(BRIDGE_DBC) $(DESTDIR)$(SHAREDIR)/beaconloc.dbc
	@if [ -e $(DESTDIR)$(SYSCONFDIR)/beaconloc/site.ini ]; then \
	    echo "install: $(DESTDIR)$(SYSCONFDIR)/beaconloc/site.ini exists: kept"; \
	else \
	    $(INSTALL) -m 0644 hw_sim/beaconloc_sim/data/scenarios/kleeman-lab.ini \
	        $(DESTDIR)$(SYSCONFDIR)/beaconloc/site.ini; \
	fi
