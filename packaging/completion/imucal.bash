# SPDX-License-Identifier: BSD-3-Clause
# bash completion for imucal, imucald and imucalctl (installed under each name). Subcommands,
# options and the choices of an option are read from the program's own --help (CLI11's
# "Subcommands:" section and option lines), so the completion follows the program; an option
# that takes TEXT completes file names.

# The subcommands listed in a --help text.
_imucal_subcommands() {
    printf '%s\n' "$1" | awk '/^Subcommands:/ { on = 1; next } on && /^  [a-z]/ { print $1 } /^$/ { on = 0 }'
}

# The long and short options of a --help text.
_imucal_options() {
    printf '%s\n' "$1" | awk '/^  -/ { n = split($1, names, ","); for (i = 1; i <= n; i++) print names[i] }'
}

# The value type CLI11 prints after option $2 in help text $1 (TEXT, FLOAT, TEXT:{a,b}, ...);
# empty for a flag.
_imucal_option_type() {
    printf '%s\n' "$1" | awk -v opt="$2" '/^  -/ {
        n = split($1, names, ",")
        for (i = 1; i <= n; i++) if (names[i] == opt) { if ($2 ~ /^[A-Z]/) print $2; exit }
    }'
}

_imucal() {
    local cur prev words cword
    _init_completion || return
    local prog=${words[0]} help i w type
    local -a path=()
    help=$("$prog" --help 2>/dev/null) || help=
    # Follow the subcommands typed so far (imucal calibrate static ...).
    for ((i = 1; i < cword; i++)); do
        w=${words[i]}
        [[ $w == -* ]] && continue
        if _imucal_subcommands "$help" | grep -qxF -- "$w"; then
            path+=("$w")
            help=$("$prog" "${path[@]}" --help 2>/dev/null) || help=
        fi
    done
    if [[ $prev == -* ]]; then
        type=$(_imucal_option_type "$help" "$prev")
        case $type in
            *:\{*\}*)
                local choices=${type#*:\{}
                choices=${choices%%\}*}
                mapfile -t COMPREPLY < <(compgen -W "${choices//,/ }" -- "$cur")
                return
                ;;
            TEXT*)
                _filedir
                return
                ;;
            ?*)
                return
                ;;
        esac
    fi
    if [[ $cur == -* ]]; then
        mapfile -t COMPREPLY < <(compgen -W "$(_imucal_options "$help")" -- "$cur")
        return
    fi
    local subcommands
    subcommands=$(_imucal_subcommands "$help")
    if [[ -n $subcommands ]]; then
        mapfile -t COMPREPLY < <(compgen -W "$subcommands" -- "$cur")
    else
        _filedir
    fi
}
complete -F _imucal imucal imucald imucalctl
