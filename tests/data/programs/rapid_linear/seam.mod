MODULE seam
  ! golden path
  CONST speeddata v_lt:=[100.000,28.648,5000,1000];
  CONST zonedata z_lt:=[FALSE,1.000,1.500,1.500,0.150,1.500,0.150];
  CONST jointtarget j1:=[[0.0000,0.0000,0.0000,0.0000,90.0000,0.0000],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget p2:=[[898.3110,240.7017,1299.0000],[0.00000000,0.13052619,-0.99144486,0.00000000],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget p3:=[[805.4036,465.0000,1299.0000],[0.00000000,0.25881905,-0.96592583,0.00000000],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  PROC main()
    ConfJ \On;
    ConfL \On;
    ! P1
    MoveAbsJ j1,v100,fine,tool0;
    MoveL p2,v_lt,z_lt,tool0\WObj:=wobj0;
    ! P2
    MoveL p3,v_lt,fine,tool0\WObj:=wobj0;
  ENDPROC
ENDMODULE
