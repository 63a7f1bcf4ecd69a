#!/bin/sh
# SPDX-License-Identifier: BSD-3-Clause
# A gzipped man page of one of imucal's programs, from its --help (help2man) with the sections
# of an include file (FILES, EXIT STATUS, SEE ALSO) and, for a program with subcommands, the
# --help of each subcommand and of theirs (imucal calibrate static). Run at install time.
#
#   make-man.sh PROGRAM NAME SECTION DESCRIPTION INCLUDE VERSION OUTPUT.gz
set -eu
prog=$1 name=$2 section=$3 description=$4 include=$5 version=$6 out=$7
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

subcommands() {
  "$@" --help 2>/dev/null | awk '/^Subcommands:/ { on = 1; next } on && /^  [a-z]/ { print $1 } /^$/ { on = 0 }'
}

# One subcommand's help as preformatted text: the program's path reads as its name, backslashes
# and a leading dot or quote are escaped for roff.
command_section() {
  printf '.SS "%s"\n.nf\n' "$name $*"
  "$prog" "$@" --help 2>/dev/null | sed -e "s|$prog|$name|g" -e 's/\\/\\e/g' -e "s/^\([.']\)/\\\\\&\1/" -e 's/-/\\-/g'
  printf '.fi\n'
}

cp "$include" "$tmp/include.h2m"
commands=$(subcommands "$prog")
if [ -n "$commands" ]; then
  {
    printf '\n[COMMANDS]\n'
    for c in $commands; do
      command_section "$c"
      for s in $(subcommands "$prog" "$c"); do command_section "$c" "$s"; done
    done
  } >>"$tmp/include.h2m"
fi
help2man --no-info --version-string="$version" --section="$section" --name="$description" \
  --include="$tmp/include.h2m" --output="$tmp/page" "$prog"
# help2man names the program by the file it ran; the page is about the installed name.
sed -i -e "s|$prog|$name|g" "$tmp/page"
gzip -9n -c "$tmp/page" >"$out"
