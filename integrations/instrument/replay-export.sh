#!/bin/sh
# An instrument program for `hexacomp-trainer campaign --instrument command`: it answers each
# reading from a file the tracker's own software exported, and shows the contract a program that
# drives a tracker's SDK follows.
#
#   hexacomp-trainer campaign --plan plan.csv --out campaign.csv --instrument command \
#       --instrument-command "replay-export.sh tracker-export.csv" --no-reference
#
# (--no-reference: an export holds the plan's configurations only, not the reference
# configuration R1, R2, ... the campaign measures again and again to watch for drift; a program
# that drives a live tracker measures those too.)
#
# The campaign runs it once per reading as
#   replay-export.sh EXPORT ID X Y Z A B C READING
# (the configuration's id, its commanded pose in mm and degrees, the reading's number from 1)
# and reads the first line it prints: the targets p1x,p1y,p1z,...,pNz in the instrument's frame
# (mm; three empty cells for a target not seen), or a 6-DoF probe's pose x,y,z,a,b,c. Exit
# status 0. Any other status, no line, or a line of the wrong width is a failed reading: the
# campaign retries it, then records the configuration as a gap.
#
# Under a --registration the campaign also asks for the fiducials at its end, as
#   replay-export.sh EXPORT --fiducial NAME X Y Z READING
# (the fiducial's nominal position in the base frame, mm), and reads the point x,y,z it prints
# (the instrument's frame, mm). An export holds no fiducials: this script then exits non-zero
# (its arguments are too few), which is a failed reading.
#
# EXPORT is a CSV file `id,reading,p1x,...`, one line per reading, header first.
set -eu
export_file=$1
id=$2
reading=$9
exec awk -F, -v id="$id" -v reading="$reading" '
    NR > 1 && $1 == id && $2 == reading {
        sub(/^[^,]*,[^,]*,/, "")
        print
        found = 1
        exit
    }
    END { exit found ? 0 : 1 }
' "$export_file"
